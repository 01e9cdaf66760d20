"""The run harness: determinism, resume after interruption, outputs, and bad input."""

import dataclasses
import json
import math
import os
import signal
import stat
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments.io import CheckpointError, load_checkpoint
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, RunError, evaluate, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150"]


def _cfg(agent="hubsgo", steps=1500, **kw):
    return RunConfig(task="keydoor", agent=agent, steps=steps, seed=3, checkpoint_steps=300,
                     overrides=TINY + ["loop.option_steps=15"], **kw)


def _rows(path):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in read_csv_rows(path / "metrics.csv")]


class Crash(Exception):
    pass


def _exact_marginals(table):
    """P(w_i = 1) under the MRF of ``subgoals.json``'s factors, by enumerating all 2^N configurations."""
    from hubsgo_ppl.distributions import state_table

    names = table["names"]
    s = state_table(len(names)).double()
    energy = s @ torch.tensor([table["factors"]["unary"][n] for n in names], dtype=torch.float64)
    for edge, j in table["factors"]["pairwise"].items():
        u, v = edge.split("--")
        energy = energy + j * s[:, names.index(u)] * s[:, names.index(v)]
    return dict(zip(names, (energy.softmax(0)[:, None] * s).sum(0).tolist()))


def test_same_seed_same_metrics_and_resume_after_crash_continues_identically(tmp_path):
    full = tmp_path / "full"
    train(_cfg(), full, progress=False)
    again = tmp_path / "again"
    train(_cfg(), again, progress=False)
    assert _rows(full) == _rows(again), "same seed on CPU must give identical metrics"

    crashed = tmp_path / "crashed"

    n_full = len(_rows(full))
    assert n_full >= 4, "the budget must span several episodes for this test to mean anything"

    def crash_after_checkpoint(stats):
        if (crashed / "checkpoint.pt").exists():    # the first episode after a checkpoint: logged, then lost
            raise Crash

    with pytest.raises(Crash):
        train(_cfg(), crashed, progress=False, on_episode=crash_after_checkpoint)
    held = load_checkpoint(crashed / "checkpoint.pt")
    assert 0 < held["episodes"] < n_full - 1 and held["env_steps"] >= 300
    assert len(_rows(crashed)) == held["episodes"] + 1
    train(_cfg(), crashed, resume=True, progress=False)
    assert _rows(crashed) == _rows(full)
    for name in ("config.yaml", "checkpoint.pt", "subgoals.json", "learning_curve.png", "critic_history.csv"):
        assert (full / name).is_file(), name
    assert list((full / "tb").glob("events.out.tfevents.*"))
    table = json.loads((full / "subgoals.json").read_text())
    assert table["num_samples"] == 10_000 and table["ranking"]
    assert table["marginals"] == pytest.approx(_exact_marginals(table), abs=1e-5)


@pytest.mark.parametrize("agent", ["hubsgo", "hdqn"])
def test_tiny_budget_trains_and_evaluates(tmp_path, agent, record_episodes):
    out = tmp_path / agent
    summary = train(_cfg(agent=agent, steps=800), out, progress=False)
    assert summary["finished"] and summary["env_steps"] >= 800
    rows = read_csv_rows(out / "metrics.csv")
    assert [int(r["episode"]) for r in rows] == list(range(len(rows)))
    result = evaluate(out, episodes=2)
    played = record_episodes                     # the eval env's own step results
    assert result["episodes"] == len(played) == 2
    assert result["success_rate"] == pytest.approx(np.mean([e["success"] for e in played]), abs=1e-12)
    assert result["returns"] == pytest.approx([e["return"] for e in played], abs=1e-12)
    assert result["mean_length"] == pytest.approx(np.mean([e["length"] for e in played]), abs=1e-12)
    for e in played:     # MiniGrid: 1 - 0.9 * steps / max_steps on reaching the goal, else 0
        assert e["max_steps"] == 150 and 1 <= e["length"] <= 150
        assert e["return"] == pytest.approx(1 - 0.9 * e["length"] / 150 if e["success"] else 0.0, abs=1e-12)
    # KeyDoor from its fixed start: 19 steps at best (BFS)
    assert result["optimal_return"] == pytest.approx(1 - 0.9 * 19 / 150, abs=1e-12)
    assert (out / "eval.json").is_file()


def test_bad_inputs_fail_clearly_and_lose_nothing(tmp_path):
    from hubsgo_ppl.envs import UnknownTaskError
    from hubsgo_ppl.specs import SpecError

    with pytest.raises(UnknownTaskError, match="unknown task 'nope'"):
        train(RunConfig(task="nope"), tmp_path / "x", progress=False)
    with pytest.raises(SpecError, match="model spec 'fourroom-specific'.*'keydoor'"):
        train(RunConfig(task="keydoor", model="fourroom-specific"), tmp_path / "y", progress=False)
    with pytest.raises(CheckpointError, match="no checkpoint"):
        train(_cfg(), tmp_path / "empty", resume=True, progress=False)
    run = tmp_path / "run"
    train(_cfg(steps=300), run, progress=False)
    before = (run / "metrics.csv").read_bytes()
    with pytest.raises(RunError, match=r"already holds a run; continue it with --resume \(resume=True from Python\)"):
        train(_cfg(steps=300), run, progress=False)
    assert (run / "metrics.csv").read_bytes() == before
    (run / "checkpoint.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="corrupt"):
        train(_cfg(steps=600), run, resume=True, progress=False)
    assert (run / "metrics.csv").read_bytes() == before
    blocker = tmp_path / "a-file"
    blocker.write_text("x")                     # a folder cannot be made under a file, even as root
    with pytest.raises(RunError, match="cannot write there"):
        train(_cfg(steps=300), blocker / "sub", progress=False)


# -- kill -9 and --resume: every file of the run directory as in an uninterrupted run --------------------

KILL_CHILD = """
import json, os, sys, time
from pathlib import Path
from hubsgo_ppl.experiments.run import RunConfig, train

out, marker = Path(sys.argv[1]), Path(sys.argv[2])
after = []

def hold(stats):
    if (out / "checkpoint.pt").exists():
        after.append(stats.episode)
        if len(after) == 2:     # two episodes logged after the checkpoint: wait here for the parent's kill -9
            marker.write_text(str(os.getpid()))
            time.sleep(600)

train(RunConfig(**json.loads(sys.argv[3])), out, progress=False, on_episode=hold)
"""


def _same(a, b, where="checkpoint"):
    """Deep equality of checkpoint contents (tensors, arrays, NaN-aware floats); fails naming the key."""
    assert type(a) is type(b), where
    if isinstance(a, dict):
        assert list(a) == list(b), where
        for k in a:
            _same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]")
    elif isinstance(a, torch.Tensor):
        assert a.dtype == b.dtype and torch.equal(a, b), where
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), where
    elif isinstance(a, float) and math.isnan(a):
        assert math.isnan(b), where
    else:
        assert a == b, where


def _no_wall(row):
    return {k: v for k, v in row.items() if "wall" not in k}


def _files(run):
    return sorted(str(p.relative_to(run)) for p in run.rglob("*") if p.is_file() and p.parent.name != "tb")


def assert_same_run(got, want):
    """Every file of run ``got`` matches run ``want`` (TensorBoard events excepted; wall times ignored)."""
    assert _files(got) == _files(want)
    assert list((got / "tb").glob("events.out.tfevents.*")) and list((want / "tb").glob("events.out.tfevents.*"))
    for name in _files(want):
        a, b = got / name, want / name
        if name.endswith(".csv"):
            rows_a, rows_b = read_csv_rows(a), read_csv_rows(b)
            assert list(rows_a[0]) == list(rows_b[0]), name                     # same columns, same order
            assert [_no_wall(r) for r in rows_a] == [_no_wall(r) for r in rows_b], name
        elif name.endswith((".yaml", ".yml")):
            assert yaml.safe_load(a.read_text()) == yaml.safe_load(b.read_text()), name
        elif name.endswith(".json"):
            assert json.loads(a.read_text()) == json.loads(b.read_text()), name
        elif name == "checkpoint.pt":
            ca, cb = load_checkpoint(a), load_checkpoint(b)
            ca.pop("wall_time"), cb.pop("wall_time")
            _same(ca, cb)
        else:
            assert a.read_bytes() == b.read_bytes(), name


def test_kill_9_then_resume_leaves_every_file_as_an_uninterrupted_run(tmp_path, capsys):
    cfg = _cfg(steps=900, history_every=1)
    full = tmp_path / "full"
    train(cfg, full, progress=False)
    n = len(_rows(full))
    assert n >= 6, "the budget must span episodes after the kill for this test to mean anything"

    run, marker = tmp_path / "killed", tmp_path / "held"
    proc = subprocess.Popen([sys.executable, "-c", KILL_CHILD, str(run), str(marker),
                             json.dumps(dataclasses.asdict(cfg))], stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while not marker.exists():
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        assert time.monotonic() < deadline, "the child never got two episodes past its first checkpoint"
        time.sleep(0.05)
    proc.kill()                                          # SIGKILL: no handler, no finally, no flush
    assert proc.wait(timeout=60) == -signal.SIGKILL
    proc.stderr.close()
    held = load_checkpoint(run / "checkpoint.pt")["episodes"]
    assert 0 < held and held + 2 < n, "the kill must leave episodes to train after it"
    logged = [str(i) for i in range(held + 2)]                               # two rows the checkpoint lacks
    assert [r["episode"] for r in _rows(run)] == logged
    assert [r["episode"] for r in read_csv_rows(run / "critic_history.csv")] == logged
    assert not (run / "subgoals.json").exists()

    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]) == 0
    assert capsys.readouterr().err == ""
    assert_same_run(run, full)
    assert len(_rows(run)) == n


def test_run_files_honour_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        run = tmp_path / "run"
        train(_cfg(steps=300), run, progress=False)
        evaluate(run, episodes=1)
    finally:
        os.umask(old)
    files = [p for p in run.rglob("*") if p.is_file()]
    names = {p.name for p in files}
    assert {"checkpoint.pt", "config.yaml", "metrics.csv", "critic_history.csv", "subgoals.json",
            "learning_curve.png", "eval.json"} <= names
    assert any(n.startswith("events.out.tfevents") for n in names)
    assert {p.name: oct(stat.S_IMODE(p.stat().st_mode)) for p in files} == {p.name: "0o644" for p in files}


def test_resume_before_the_first_checkpoint_starts_afresh(tmp_path, capsys):
    cfg = _cfg(steps=600)
    cfg.checkpoint_steps = 10_000
    fresh = tmp_path / "fresh"
    train(cfg, fresh, progress=False)

    def crash(stats):
        if stats.episode == 1:
            raise Crash

    run = tmp_path / "run"
    with pytest.raises(Crash):
        train(cfg, run, progress=False, on_episode=crash)
    assert not (run / "checkpoint.pt").exists()
    assert (run / "config.yaml").is_file() and len(_rows(run)) == 2
    (run / "notes.txt").write_text("not the run's")
    capsys.readouterr()
    train(cfg, run, resume=True, progress=False)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no checkpoint" in err[0] and "afresh" in err[0], err
    assert "metrics.csv" in err[0] and "config.yaml" in err[0]
    assert (run / "notes.txt").read_text() == "not the run's"
    (run / "notes.txt").unlink()
    assert len(list((run / "tb").glob("events.out.tfevents.*"))) == 1        # the partial events went too
    assert_same_run(run, fresh)


def test_the_agent_is_built_with_the_runs_torch_threads(tmp_path, monkeypatch):
    # a sweep worker sets one thread before anything is built; `hubsgo train` must too, or float
    # reductions made while building (and after) can differ from the sweep's run of the same config
    import hubsgo_ppl.experiments.driver as driver

    seen = []
    real_build = driver.build_run

    def build(resolved):
        seen.append(torch.get_num_threads())
        return real_build(resolved)

    monkeypatch.setattr(driver, "build_run", build)
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(2)
        train(_cfg(steps=300), tmp_path / "run", progress=False)
    finally:
        torch.set_num_threads(before)
    assert seen == [1]


@pytest.mark.parametrize("error", [RuntimeError, KeyboardInterrupt, FloatingPointError])
def test_an_exception_closes_the_writer_and_the_env(tmp_path, monkeypatch, error):
    import hubsgo_ppl.experiments.driver as driver
    from hubsgo_ppl.experiments.logger import TensorBoardOutput

    seen = {"env_closed": 0, "writers": []}

    class SpyTB(TensorBoardOutput):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            seen["writers"].append(self.writer)

    real_build = driver.build_run

    def build(resolved):
        env, agent = real_build(resolved)
        real_close, real_chunk = env.close, agent.train_chunk

        def close():
            seen["env_closed"] += 1
            real_close()

        def chunk():
            yield from real_chunk()
            raise error("the trainer failed")

        env.close, agent.train_chunk = close, chunk
        return env, agent

    monkeypatch.setattr(driver, "TensorBoardOutput", SpyTB)
    monkeypatch.setattr(driver, "build_run", build)
    expected = RunError if error is KeyboardInterrupt else error
    with pytest.raises(expected):
        train(_cfg(steps=300), tmp_path / "run", progress=True)
    assert len(seen["writers"]) == 1 and seen["writers"][0].all_writers is None, "TensorBoard writer left open"
    assert seen["env_closed"] == 1
    assert len(_rows(tmp_path / "run")) == 1


def test_set_numbers_in_e_notation_and_bad_keys():
    from hubsgo_ppl.experiments.run import resolve

    hyper = resolve(RunConfig(task="keydoor", overrides=["high.lr=3e-4", "low.buffer_size=1e5",
                                                         "loop.option_steps=12"]))["hyper"]
    assert hyper["high"]["lr"] == 3e-4 and isinstance(hyper["high"]["lr"], float)
    assert hyper["low"]["buffer_size"] == 100_000 and isinstance(hyper["low"]["buffer_size"], int)
    assert hyper["loop"]["option_steps"] == 12
    with pytest.raises(RunError, match=r"unknown key 'nonsense' in section 'loop'.*valid keys: .*option_steps"):
        resolve(RunConfig(task="keydoor", overrides=["loop.nonsense=3"]))
    with pytest.raises(RunError, match=r"unknown key 'learning_rate' in section 'hiro'.*valid keys: .*temperature"):
        resolve(RunConfig(task="keydoor", agent="hiro", overrides=["hiro.learning_rate=1e-3"]))
    assert resolve(RunConfig(task="keydoor", agent="hiro", overrides=["hiro.lr=1e-3"]))["hyper"]["hiro"]["lr"] == 1e-3
