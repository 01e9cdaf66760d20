"""Checkpoints: a full disk keeps the previous one; a damaged config is refused in one line everywhere."""

import errno

import pytest
import torch

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments import RunConfig, train
from hubsgo_ppl.experiments.io import load_checkpoint

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def _cfg(steps):
    return RunConfig(task="keydoor", steps=steps, seed=3, checkpoint_steps=300, overrides=TINY)


@pytest.mark.parametrize("failure", ["torch", "enospc"])
def test_a_full_disk_during_a_checkpoint_is_one_line_and_keeps_the_previous_one(tmp_path, monkeypatch, capsys,
                                                                              failure):
    out = tmp_path / "run"
    train(_cfg(300), out, progress=False)
    before = (out / "checkpoint.pt").read_bytes()
    real_save = torch.save

    def full(obj, fh, *args, **kwargs):
        fh.write(b"PK\x03\x04 half a zip")          # the start of a checkpoint, then the disk is full
        if failure == "torch":
            raise RuntimeError("[enforce fail at inline_container.cc:672] . PytorchStreamWriter failed writing file "
                               "data/0: file write failed")
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(torch, "save", full)
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(out), "--resume", "--steps", "600", "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "cannot write the checkpoint" in err[0] and "previous checkpoint is intact" in err[0], err
    monkeypatch.setattr(torch, "save", real_save)
    assert (out / "checkpoint.pt").read_bytes() == before
    assert [p.name for p in out.iterdir() if ".tmp" in p.name] == []
    assert main(["train", "keydoor", "--out", str(out), "--resume", "--steps", "600", "--no-progress"]) == 0


def test_a_checkpoint_with_a_damaged_config_is_one_line_in_every_command(tmp_path, capsys):
    out = tmp_path / "run"
    train(_cfg(300), out, progress=False)
    ckpt = load_checkpoint(out / "checkpoint.pt")
    ckpt["config"]["hyper"] = "not a mapping"
    torch.save(ckpt, out / "checkpoint.pt")
    (out / "config.yaml").unlink()          # the checkpoint's copy is the one read
    for command in (["evaluate", str(out), "--episodes", "1"], ["subgoals", str(out), "--recompute"],
                    ["diagnose", str(out), "--chains", "2", "--draws", "10"],
                    ["train", "keydoor", "--out", str(out), "--resume", "--no-progress"]):
        capsys.readouterr()
        assert main(command) == 2, command
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "damaged: hyper is the str 'not a mapping'" in err[0], (command, err)
    assert not (out / "config.yaml").exists() and load_checkpoint(out / "checkpoint.pt")["config"]["hyper"] == \
        "not a mapping", "nothing rewritten"


@pytest.mark.parametrize("verb", ["subgoals", "evaluate", "review"])
def test_the_out_folder_of_a_seeds_run_names_its_seed_runs(tmp_path, capsys, verb):
    for seed in (0, 1):   # what `hubsgo train --seeds 0 1 --out OUT` leaves: OUT/seed0, OUT/seed1
        (tmp_path / f"seed{seed}").mkdir()
        (tmp_path / f"seed{seed}" / "checkpoint.pt").write_bytes(b"")
    assert main([verb, str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds one run per seed of `hubsgo train --seeds` (seed0, seed1)" in err[0], err
    assert f"e.g. {tmp_path / 'seed0'}" in err[0]
