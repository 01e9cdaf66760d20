"""`hubsgo revise` writes the run where it lies and has no --out: its refusals say so, not "choose another
--out" (a flag it does not take)."""

from __future__ import annotations

import errno
import os

import pytest

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments.lock import run_folder_lock

TINY = ["--set", "high.learning_starts=8", "--set", "high.batch_size=8", "--set", "low.learning_starts=64",
        "--set", "low.batch_size=32", "--set", "low.hidden=[32]", "--set", "high.hidden=[32]",
        "--set", "loop.option_steps=15", "--set", "env.max_steps=150"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("revise") / "run"
    assert main(["train", "keydoor", "--steps", "300", "--out", str(out), "--no-progress", *TINY]) == 0
    return out


def _error(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("hubsgo: error")]
    assert len(err) == 1, err
    return err[0]


def test_revise_while_another_process_writes_the_run_names_no_out_flag(run, capsys):
    capsys.readouterr()
    with run_folder_lock(run):
        assert main(["revise", str(run), "--model", "keydoor-specific", "--no-train"]) == 2
    line = _error(capsys)
    assert "another process is writing this run folder" in line and "--out" not in line


def test_revise_of_a_run_folder_it_cannot_write_names_no_out_flag(run, capsys, monkeypatch):
    real_open = os.open

    def read_only(path, flags, *args, **kwargs):
        if str(path).endswith(".lock"):
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr("hubsgo_ppl.experiments.lock.os.open", read_only)
    capsys.readouterr()
    assert main(["revise", str(run), "--model", "keydoor-specific", "--no-train"]) == 2
    line = _error(capsys)
    assert "Read-only file system" in line and "--out" not in line
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]) == 2
    assert "--out" in _error(capsys)          # train, which takes --out, still names it
