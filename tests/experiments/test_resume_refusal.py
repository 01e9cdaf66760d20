"""A `--resume` that is refused leaves the run as it was: its logs are cut back to the checkpoint only
once the resume goes ahead."""

from __future__ import annotations

from hubsgo_ppl.cli import main

TINY = ["--set", "high.learning_starts=8", "--set", "high.batch_size=8", "--set", "low.learning_starts=64",
        "--set", "low.batch_size=32", "--set", "low.hidden=[32]", "--set", "high.hidden=[32]",
        "--set", "loop.option_steps=15", "--set", "env.max_steps=150"]
FILES = ("metrics.csv", "critic_history.csv", "subgoals.json", "config.yaml")


def test_a_resume_refused_for_a_budget_below_the_steps_taken_keeps_every_file(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "keydoor", "--steps", "300", "--out", str(out), "--no-progress", *TINY]) == 0
    before = {name: (out / name).read_bytes() for name in FILES}
    assert b",final," in before["critic_history.csv"] or b",settled," in before["critic_history.csv"]
    capsys.readouterr()
    assert main(["train", "keydoor", "--steps", "200", "--out", str(out), "--resume", "--no-progress"]) == 2
    assert "has already taken" in capsys.readouterr().err
    assert {name: (out / name).read_bytes() for name in FILES} == before


def test_a_resume_refused_while_rebuilding_the_run_keeps_every_file(tmp_path, capsys, monkeypatch):
    """As a run whose env or critic class cannot be imported in this process (PYTHONPATH unset)."""
    from hubsgo_ppl.experiments import driver
    from hubsgo_ppl.experiments.resolved import RunError

    out = tmp_path / "run"
    assert main(["train", "keydoor", "--steps", "300", "--out", str(out), "--no-progress", *TINY]) == 0
    before = {name: (out / name).read_bytes() for name in FILES}

    def cannot_import(*args, **kwargs):
        raise RunError("cannot import 'my_env'; add its folder to PYTHONPATH")

    monkeypatch.setattr(driver, "restore", cannot_import)
    capsys.readouterr()
    assert main(["train", "keydoor", "--steps", "600", "--out", str(out), "--resume", "--no-progress"]) == 2
    assert "cannot import" in capsys.readouterr().err
    assert {name: (out / name).read_bytes() for name in FILES} == before


def test_seeds_resumed_together_are_refused_before_any_seeds_logs_are_cut(tmp_path, capsys):
    out = tmp_path / "runs"
    assert main(["train", "keydoor", "--seeds", "0", "1", "--steps", "300", "--out", str(out), "--no-progress",
                 *TINY]) == 0
    assert main(["train", "keydoor", "--steps", "900", "--out", str(out / "seed1"), "--resume", "--no-progress"]) == 0
    before = {(seed, name): (out / seed / name).read_bytes() for seed in ("seed0", "seed1") for name in FILES}
    capsys.readouterr()
    # seed 0 could go on to 600 steps, seed 1 has passed them: refused, and neither run is touched
    assert main(["train", "keydoor", "--seeds", "0", "1", "--steps", "600", "--out", str(out), "--resume",
                 "--no-progress"]) == 2
    assert "seed1: the run has already taken" in capsys.readouterr().err
    assert {(seed, name): (out / seed / name).read_bytes() for seed in ("seed0", "seed1") for name in FILES} == before
