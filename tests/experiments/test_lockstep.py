"""Seeds trained in lockstep (``hubsgo train TASK --seeds ...``): each seed's folder is the run that seed
makes alone, to the bit; a lockstep run resumes after an interruption; every verb reads its folders."""

import csv

import pytest

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments import driver
from hubsgo_ppl.experiments.seeds import seed_folders, train_seeds
from hubsgo_ppl.experiments.run import RunConfig, RunError, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "loop.option_steps=15", "env.max_steps=150"]


def _cfg(steps=450, **kw):
    return RunConfig(task="keydoor", steps=steps, overrides=list(TINY), checkpoint_steps=150, **kw)


def _rows(folder):
    with open(folder / "metrics.csv") as f:
        return [{k: v for k, v in row.items() if k != "wall_time"} for row in csv.DictReader(f)]


@pytest.fixture(scope="module")
def lockstep(tmp_path_factory):
    out = tmp_path_factory.mktemp("lockstep")
    summaries = train_seeds(_cfg(), [0, 1], seed_folders(out, [0, 1]), progress=False)
    return out, summaries


def test_each_lockstep_seed_equals_the_seed_run_alone_and_is_reproducible(lockstep, tmp_path):
    out, summaries = lockstep
    assert [s["finished"] for s in summaries] == [True, True]
    again = train_seeds(_cfg(), [0, 1], seed_folders(tmp_path / "again", [0, 1]), progress=False)
    assert [s["env_steps"] for s in again] == [s["env_steps"] for s in summaries]
    for seed in (0, 1):
        rows = _rows(out / f"seed{seed}")
        assert len(rows) > 2 and float(rows[-1]["env_steps"]) >= 450
        assert _rows(tmp_path / "again" / f"seed{seed}") == rows
    alone = tmp_path / "alone1"
    train(_cfg(seed=1), alone, progress=False)
    assert _rows(alone) == _rows(out / "seed1")
    assert _rows(out / "seed0") != _rows(out / "seed1")


def test_an_interrupted_lockstep_run_resumes_to_the_uninterrupted_files(lockstep, tmp_path, monkeypatch):
    out, _ = lockstep
    folders = seed_folders(tmp_path / "cut", [0, 1])
    log, calls = driver.RunSession.log, []

    def interrupted(session, stats):
        log(session, stats)
        calls.append(1)
        if session.agent.env_steps > 320 and (session.out / "checkpoint.pt").exists():
            raise KeyboardInterrupt

    monkeypatch.setattr(driver.RunSession, "log", interrupted)
    with pytest.raises(RunError, match="seed 0: interrupted; .* holds the last checkpoint"):
        train_seeds(_cfg(), [0, 1], folders, progress=False)
    monkeypatch.setattr(driver.RunSession, "log", log)
    assert all((f / "checkpoint.pt").exists() for f in folders)
    assert any(len(_rows(f)) < len(_rows(out / f.name)) for f in folders)
    summaries = train_seeds(_cfg(), [0, 1], folders, resume=True, progress=False)
    assert [s["finished"] for s in summaries] == [True, True]
    for f in folders:
        assert _rows(f) == _rows(out / f.name)
        assert (f / "subgoals.json").exists()


def test_every_verb_reads_a_lockstep_seeds_folder(lockstep, capsys):
    out, _ = lockstep
    run = str(out / "seed1")
    assert main(["subgoals", run]) == 0
    assert "marginals P(w=1)" in capsys.readouterr().out
    assert main(["evaluate", run, "--episodes", "2"]) == 0
    assert "greedy return" in capsys.readouterr().out
    assert main(["review", run, "--no-gif"]) == 0
    assert main(["diagnose", run, "--chains", "2", "--draws", "50", "--burn-in", "5"]) == 0


def test_the_cli_trains_seeds_into_out_seedk_and_refuses_mixed_flags(tmp_path, capsys):
    sets = [x for kv in TINY for x in ("--set", kv)]
    assert main(["train", "keydoor", "--seeds", "3", "4", "--steps", "150", "--out", str(tmp_path / "r"),
                 "--no-progress", *sets]) == 0
    printed = capsys.readouterr().out
    assert f"run: {tmp_path / 'r' / 'seed3'}" in printed and f"run: {tmp_path / 'r' / 'seed4'}" in printed
    assert main(["train", "keydoor", "--seeds", "3", "4", "--seed", "1", "--out", str(tmp_path / "x")]) == 2
    assert "give either --seed or --seeds" in capsys.readouterr().err
    assert main(["train", "keydoor", "--seeds", "3", "3", "--out", str(tmp_path / "y")]) == 2
    assert "lists a seed twice" in capsys.readouterr().err
    assert main(["train", "keydoor", "--seeds", "3", "4", "--stop-at", "100", "--out", str(tmp_path / "z")]) == 2
    assert "--stop-at applies to one run" in capsys.readouterr().err


def test_shares_split_the_seeds_into_consecutive_runs_one_per_worker():
    from hubsgo_ppl.experiments.seeds import shares

    assert [list(r) for r in shares(5, 2)] == [[0, 1, 2], [3, 4]]
    assert [list(r) for r in shares(5, 3)] == [[0, 1], [2], [3, 4]]
    assert [list(r) for r in shares(2, 8)] == [[0], [1]]
    assert [list(r) for r in shares(3, 1)] == [[0, 1, 2]]


def test_seeds_shared_between_worker_processes_give_each_seeds_own_files(lockstep, tmp_path, capsys):
    out, _ = lockstep
    sets = [x for kv in TINY for x in ("--set", kv)]
    args = ["train", "keydoor", "--seeds", "0", "1", "--steps", "450", "--checkpoint-steps", "150",
            "--workers", "2", "--out", str(tmp_path / "w"), "--no-progress", *sets]
    assert main(args) == 0
    for seed in (0, 1):
        assert _rows(tmp_path / "w" / f"seed{seed}") == _rows(out / f"seed{seed}")
    capsys.readouterr()
    assert main(args) == 2          # a worker's refusal comes back as the command's one line
    err = capsys.readouterr().err
    assert err.count("already holds a run") == 2 and "Traceback" not in err
    assert main(["train", "keydoor", "--seed", "0", "--workers", "2", "--out", str(tmp_path / "v")]) == 2
    assert "--workers shares the seeds of --seeds" in capsys.readouterr().err


def test_the_process_that_hands_its_seeds_to_workers_imports_no_torch_and_says_a_shared_refusal_once(tmp_path):
    import subprocess
    import sys

    code = ("import sys; from hubsgo_ppl.cli import main; "
            "rc = main(['train', 'nosuch', '--seeds', '0', '1', '--workers', '2', '--out', sys.argv[1]]); "
            "print(rc, 'torch' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code, str(tmp_path / "w")], capture_output=True, text=True,
                          timeout=300)
    assert done.stdout.split() == ["2", "False"], done.stderr
    assert done.stderr.count("unknown task 'nosuch'") == 1 and "Traceback" not in done.stderr


_ORPHAN_PARENT = """
import multiprocessing as mp, sys, time
from pathlib import Path

def child(marker):
    from hubsgo_ppl.experiments.seeds import stop_with_parent
    stop_with_parent(interval=0.05)
    Path(marker + ".started").write_text("")
    try:
        while True:
            time.sleep(0.01)
    except KeyboardInterrupt:           # what a run's own handling sees: it stops where it is
        Path(marker).write_text("interrupted")

if __name__ == "__main__":
    proc = mp.get_context("spawn").Process(target=child, args=(sys.argv[1],))
    proc.start()
    time.sleep(600)
"""


def test_a_worker_whose_parent_is_killed_is_interrupted_and_stops(tmp_path):
    """Killing the process that spawned the seeds' or a sweep's workers (SIGKILL: it cannot stop them
    itself) interrupts each worker as Ctrl-C would, even where SIGINT is ignored, instead of leaving it
    training on, unseen, holding its run folders' locks."""
    import signal
    import subprocess
    import sys
    import time

    script, marker = tmp_path / "parent.py", tmp_path / "marker"
    script.write_text(_ORPHAN_PARENT)
    parent = subprocess.Popen([sys.executable, str(script), str(marker)],
                              preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "marker.started").exists():
            assert time.monotonic() < deadline and parent.poll() is None
            time.sleep(0.05)
        assert not marker.exists()
        parent.kill()
        parent.wait()
        deadline = time.monotonic() + 20
        while not marker.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert marker.read_text() == "interrupted"
    finally:
        if parent.poll() is None:
            parent.kill()
