"""The run folder lock: a second process writing the same run folder is refused in one line."""

import subprocess
import sys
import time

import pytest

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments import RunConfig, RunError
from hubsgo_ppl.experiments.lock import LOCK_FILE, run_folder_lock

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]

HOLD = """
import sys, time
from hubsgo_ppl.experiments.lock import run_folder_lock
with run_folder_lock(sys.argv[1]):
    open(sys.argv[2], "w").write("held")
    time.sleep(120)
"""


@pytest.fixture
def held(tmp_path):
    """A run folder whose lock another process holds."""
    out, marker = tmp_path / "run", tmp_path / "held"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(out), str(marker)])
    deadline = time.monotonic() + 60
    while not marker.exists():
        assert proc.poll() is None and time.monotonic() < deadline
        time.sleep(0.05)
    yield out
    proc.kill()
    proc.wait(timeout=30)


def _args(seed):
    args = ["train", "keydoor", "--seed", str(seed), "--steps", "300", "--checkpoint-steps", "300", "--no-progress"]
    for item in TINY:
        args += ["--set", item]
    return args


def test_a_second_train_or_resume_on_a_locked_folder_is_refused(held, capsys):
    (held / "notes.txt").write_text("mine")
    for extra in ([], ["--resume"]):
        capsys.readouterr()
        assert main(_args(1) + ["--out", str(held)] + extra) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "another process is writing this run folder" in err[0], err
    assert sorted(p.name for p in held.iterdir()) == [LOCK_FILE, "notes.txt"], "nothing written or removed"


def test_the_lock_file_goes_with_the_lock(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    with run_folder_lock(out) as created:
        assert not created and (out / LOCK_FILE).is_file()
    assert list(out.iterdir()) == []


def test_the_lock_is_released_when_train_returns(tmp_path):
    from hubsgo_ppl.experiments import train

    out = tmp_path / "run"
    train(RunConfig(task="keydoor", steps=300, seed=1, checkpoint_steps=300, overrides=TINY), out, progress=False)
    with run_folder_lock(out):          # free again
        with pytest.raises(RunError, match="another process"):
            with run_folder_lock(out):
                pass


def test_a_folder_the_lock_created_goes_when_nothing_was_written(tmp_path):
    out = tmp_path / "new" / "run"
    with run_folder_lock(out) as created:
        assert created and (out / LOCK_FILE).is_file()
    assert not out.exists() and out.parent.is_dir()


def test_a_revision_of_a_run_another_process_writes_is_refused_and_changes_nothing(tmp_path, capsys):
    """`hubsgo revise` takes the same lock as `train`: while a process holds it, the revision is refused
    in one line and neither the checkpoint nor config.yaml changes."""
    out = tmp_path / "run"
    assert main(_args(0) + ["--out", str(out)]) == 0
    before = {name: (out / name).read_bytes() for name in ("checkpoint.pt", "config.yaml")}
    marker = tmp_path / "held"
    proc = subprocess.Popen([sys.executable, "-c", HOLD, str(out), str(marker)])
    try:
        deadline = time.monotonic() + 60
        while not marker.exists():
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        capsys.readouterr()
        assert main(["revise", str(out), "--model", "keydoor-independent", "--steps", "600", "--no-progress"]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "another process is writing this run folder" in err[0], err
    finally:
        proc.kill()
        proc.wait(timeout=30)
    assert {name: (out / name).read_bytes() for name in before} == before
