"""The command-line help is a reference of its own: every option that has a default says it, and every
output folder of a read-out can be moved out of the run folder (a run one may read but not write)."""

from __future__ import annotations

import argparse

from hubsgo_ppl.cli import build_parser, main

TINY = ["--set", "high.learning_starts=8", "--set", "high.batch_size=8", "--set", "low.learning_starts=64",
        "--set", "low.batch_size=32", "--set", "low.hidden=[32]", "--set", "high.hidden=[32]",
        "--set", "loop.option_steps=15", "--set", "env.max_steps=150"]


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_option_with_a_default_names_it_in_its_help():
    missing = []
    for name, parser in _commands().items():
        for action in parser._actions:
            if not action.option_strings or isinstance(action, argparse._HelpAction):
                continue
            if action.default in (None, False, argparse.SUPPRESS) or action.required:
                continue
            if "default" not in (action.help or ""):
                missing.append(f"{name} {action.option_strings[0]}")
    assert not missing, missing


def test_diagnose_writes_elsewhere_with_out_and_leaves_the_run_folder_as_it_was(tmp_path, capsys):
    run, out = tmp_path / "run", tmp_path / "diag"
    assert main(["train", "keydoor", "--steps", "300", "--out", str(run), "--no-progress", *TINY]) == 0
    before = sorted(p.name for p in run.iterdir())
    assert main(["diagnose", str(run), "--chains", "2", "--draws", "20", "--burn-in", "2", "--out", str(out)]) == 0
    assert sorted(p.name for p in run.iterdir()) == before
    assert {"summary.csv", "trace.png", "mrf_graph.png", "posterior.nc"} <= {p.name for p in out.iterdir()}
    assert f"summary: {out / 'summary.csv'}" in capsys.readouterr().out



def test_read_outs_refuse_an_unwritable_destination_before_any_work(tmp_path, capsys, monkeypatch):
    import tempfile

    from hubsgo_ppl.diagnostics import diagnose, render, review

    run = tmp_path / "run"
    assert main(["train", "keydoor", "--steps", "300", "--out", str(run), "--no-progress", *TINY]) == 0
    capsys.readouterr()

    def read_only(*args, **kwargs):
        raise OSError(30, "Read-only file system")

    def no_work(*args, **kwargs):
        raise AssertionError("work started before the destination was checked")

    monkeypatch.setattr(tempfile, "TemporaryFile", read_only)
    monkeypatch.setattr(diagnose, "diagnose", no_work)
    monkeypatch.setattr(review, "review", no_work)
    monkeypatch.setattr(render, "render_episode", no_work)
    for command, default in (("diagnose", "RUN_DIR/diagnostics"), ("review", "RUN_DIR/review"),
                             ("render", "RUN_DIR/episode.gif")):
        assert main([command, str(run)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"hubsgo: error: {run}: cannot write here (Read-only file system; the default is {default}); "
                       "give --out, a place you can write"], err


def test_the_seeds_help_says_which_runs_train_in_lockstep_and_which_one_after_another():
    train = _commands()["train"]
    helps = {a.option_strings[0]: " ".join(a.help.split()) for a in train._actions if a.option_strings}
    assert "learned low level of a task with discrete actions" in helps["--seeds"]
    assert "other runs (arm tasks, baselines) one seed after another" in helps["--seeds"]
    assert "lockstep" not in helps["--workers"]      # a worker trains its share as --seeds does, in lockstep or not
