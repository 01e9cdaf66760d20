"""The `hubsgo` command line: verbs work end to end; bad input gives one clear line and exit code 2."""

import shutil
import subprocess
import sys

import pytest

from hubsgo_ppl.cli import main

TINY = ["--set", "high.learning_starts=8", "--set", "high.batch_size=8", "--set", "low.learning_starts=64",
        "--set", "low.batch_size=32", "--set", "low.hidden=[32]", "--set", "high.hidden=[32]",
        "--set", "loop.option_steps=15", "--set", "env.max_steps=150"]


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    return err[0]


def test_tasks_lists_every_task_with_its_catalogue(capsys):
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    for name in ("keydoor", "fourroom", "keydoor_incorrect", "fourroom_incorrect"):
        assert f"{name}  (minigrid" in out
    assert "yellow_key" in out and "door_top" in out


def test_train_subgoals_evaluate_round_trip(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "keydoor", "--steps", "600", "--seed", "1", "--out", str(run), "--no-progress",
                 *TINY]) == 0
    out = capsys.readouterr().out
    assert "G* from 10,000 critic samples" in out
    assert main(["subgoals", str(run)]) == 0
    table = capsys.readouterr().out
    assert "rank" in table and "marginals P(w=1)" in table
    assert main(["evaluate", str(run), "--episodes", "2"]) == 0
    assert "greedy return" in capsys.readouterr().out


@pytest.mark.parametrize("argv, needle", [
    (["train", "nope"], "unknown task 'nope'"),
    (["train", "keydoor", "--model", "fourroom-specific"], "model spec 'fourroom-specific'"),
    (["train", "keydoor", "--model", "no-such-spec"], "no-such-spec"),
    (["evaluate", "/nonexistent/run"], "no such run directory"),
    (["subgoals", "/nonexistent/run"], "no such run directory"),
])
def test_bad_input_one_line_exit_2(argv, needle, capsys, tmp_path):
    if argv[0] == "train":
        argv = argv + ["--out", str(tmp_path / "o"), "--no-progress"]
    assert main(argv) == 2
    assert needle in _one_error_line(capsys)


def test_corrupt_checkpoint_is_reported_and_kept(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.pt").write_bytes(b"\x80garbage")
    assert main(["evaluate", str(run)]) == 2
    assert "corrupt" in _one_error_line(capsys)
    assert (run / "checkpoint.pt").read_bytes() == b"\x80garbage"


def test_console_script_is_installed():
    exe = shutil.which("hubsgo") or str(__import__("pathlib").Path(sys.executable).parent / "hubsgo")
    res = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "train" in res.stdout
