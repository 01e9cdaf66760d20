"""The training driver: --resume continues exactly the recorded run or refuses; Ctrl-C anywhere, a
symlinked log: one line, exit 2, nothing lost."""

import pytest
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments import RunConfig, RunError, train
from hubsgo_ppl.experiments.logger import read_csv_rows

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def _cfg(agent="hdqn", steps=600, checkpoint_steps=2000):
    return RunConfig(task="keydoor", agent=agent, steps=steps, seed=3, checkpoint_steps=checkpoint_steps,
                     overrides=list(TINY))


def _rows(run, name="metrics.csv"):
    return [{k: v for k, v in r.items() if "wall" not in k} for r in read_csv_rows(run / name)]


class Crash(Exception):
    pass


def _crash_at(episode, error=Crash):
    def hook(stats):
        if stats.episode == episode:
            raise error
    return hook


def _one_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_resume_before_the_first_checkpoint_rebuilds_the_recorded_run(tmp_path, capsys):
    fresh = tmp_path / "fresh"
    train(_cfg(), fresh, progress=False)
    run = tmp_path / "run"
    with pytest.raises(Crash):
        train(_cfg(), run, progress=False, on_episode=_crash_at(1))
    recorded = (run / "config.yaml").read_text()
    assert not (run / "checkpoint.pt").exists()
    capsys.readouterr()
    # no flags: the recorded agent (hdqn), seed 3, budget, checkpoint_steps and --set, not the defaults
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]) == 0
    assert "afresh with the settings config.yaml records" in capsys.readouterr().err
    assert yaml.safe_load((run / "config.yaml").read_text()) == yaml.safe_load(recorded)
    assert _rows(run) == _rows(fresh)


def test_resume_before_the_first_checkpoint_refuses_what_it_cannot_rebuild(tmp_path, capsys):
    run = tmp_path / "run"
    with pytest.raises(Crash):
        train(_cfg(), run, progress=False, on_episode=_crash_at(1))
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--steps", "900", "--no-progress"]) == 2
    assert "drop --steps" in _one_line(capsys)
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--seed", "0", "--no-progress"]) == 2
    assert "--seed 0 (the run's is 3)" in _one_line(capsys)
    # a plain train with other settings does not replace the recorded run either
    with pytest.raises(RunError, match="other settings"):
        train(_cfg(agent="hubsgo"), run, progress=False)
    files = sorted(p.name for p in run.iterdir())
    (run / "config.yaml").write_text("task: [damaged")
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]) == 2
    assert "config.yaml is missing or damaged" in _one_line(capsys)
    assert sorted(p.name for p in run.iterdir()) == files and (run / "config.yaml").read_text() == "task: [damaged"


def test_ctrl_c_before_the_first_checkpoint_says_so(tmp_path):
    run = tmp_path / "run"
    with pytest.raises(RunError) as caught:
        train(_cfg(), run, progress=False, on_episode=_crash_at(1, KeyboardInterrupt))
    msg = str(caught.value)
    assert "before the run's first checkpoint" in msg and "holds the last checkpoint" not in msg
    assert (run / "config.yaml").is_file() and len(_rows(run)) == 2


def test_ctrl_c_at_start_up_is_one_line_and_leaves_no_folder(tmp_path, monkeypatch, capsys):
    import hubsgo_ppl.experiments.driver as driver

    def interrupted(run):
        raise KeyboardInterrupt

    monkeypatch.setattr(driver, "build_run", interrupted)
    out = tmp_path / "run"
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(out), "--no-progress"]) == 2
    assert "interrupted before the run started; nothing was written" in _one_line(capsys)
    assert not out.exists()


def test_ctrl_c_during_the_final_g_star_keeps_the_run_and_resume_finishes_it(tmp_path, monkeypatch, capsys):
    import hubsgo_ppl.experiments.callbacks as callbacks

    real = callbacks.g_star_table

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(callbacks, "g_star_table", interrupted)
    out = tmp_path / "run"
    args = ["train", "keydoor", "--out", str(out), "--seed", "3", "--steps", "300", "--checkpoint-steps", "300",
            "--no-progress"] + [a for item in TINY for a in ("--set", item)]
    capsys.readouterr()
    assert main(args) == 2
    assert "holds its final checkpoint" in _one_line(capsys)
    assert not (out / "subgoals.json").exists()
    monkeypatch.setattr(callbacks, "g_star_table", real)
    assert main(["train", "keydoor", "--out", str(out), "--resume", "--no-progress"]) == 0
    assert (out / "subgoals.json").is_file()


def test_a_symlinked_log_is_refused_never_appended_through(tmp_path, capsys):
    run = tmp_path / "run"
    train(_cfg(agent="hubsgo", steps=300, checkpoint_steps=300), run, progress=False)
    target = tmp_path / "elsewhere.csv"
    target.write_bytes((run / "metrics.csv").read_bytes())
    (run / "metrics.csv").unlink()
    (run / "metrics.csv").symlink_to(target)
    before = target.read_bytes()
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--steps", "600", "--no-progress"]) == 2
    assert "a symbolic link" in _one_line(capsys)
    assert target.read_bytes() == before and (run / "metrics.csv").is_symlink()


@pytest.mark.parametrize("flag", [["--steps", "0"], ["--set", "steps=0"]])
def test_a_zero_budget_is_refused_the_same_way_by_either_flag(tmp_path, capsys, flag):
    out = tmp_path / "run"
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(out), "--no-progress", *flag]) == 2
    assert "steps takes an integer >= 1 (default 40000), got 0" in _one_line(capsys)   # one check, one line
    assert not out.exists()


def test_resume_with_the_runs_own_model_prints_no_default_budget_note(tmp_path, capsys):
    """A catalogue without a budget of its own: the --model check of --resume must not say the family's
    default budget is used, when the run has its own --steps."""
    from pathlib import Path

    from hubsgo_ppl.experiments.resolve import resolve
    from hubsgo_ppl.experiments.restore import check_resume

    arms = Path(__file__).resolve().parents[2] / "examples" / "arms"
    task, spec = str(arms / "push_four.yaml"), str(arms / "push_four-spec.yaml")
    run = tmp_path / "run"
    run.mkdir()
    config = resolve(RunConfig(task=task, model=spec, steps=1500, low_level="learned"))
    (run / "config.yaml").write_text(yaml.safe_dump(config))
    capsys.readouterr()
    check_resume(run, task, model=spec)
    assert "no --steps" not in capsys.readouterr().err


@pytest.mark.parametrize("files", [{"metrics.csv": "epoch,loss\n1,0.5\n"}, {"critic_history.csv": "step,value\n"},
                                   {"config.yaml": "my: notes\n", "learning_curve.png": "mine"}])
def test_a_folder_of_the_users_own_files_under_a_runs_names_is_refused_not_emptied(tmp_path, files):
    run = tmp_path / "mine"
    run.mkdir()
    for name, text in files.items():
        (run / name).write_text(text)
    with pytest.raises(RunError, match="not written by `hubsgo train`"):
        train(_cfg(), run, progress=False)
    assert {p.name: p.read_text() for p in run.iterdir()} == files


def test_a_run_is_neither_trained_over_the_seed_folders_of_another_nor_inside_a_run(tmp_path, capsys):
    train(_cfg(steps=200), tmp_path / "runs" / "seed0", progress=False)
    before = sorted(p.name for p in (tmp_path / "runs").iterdir())
    with pytest.raises(RunError, match=r"runs holds runs of its own \(seed0\)"):
        train(_cfg(steps=200), tmp_path / "runs", progress=False)
    with pytest.raises(RunError, match="seed0 is a run's folder"):
        train(_cfg(steps=200), tmp_path / "runs" / "seed0" / "seed1", progress=False)
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == before
    assert not (tmp_path / "runs" / "seed0" / "seed1").exists()


def test_a_python_resume_refuses_a_config_that_names_another_run_and_takes_its_defaults_as_the_runs_own(tmp_path):
    out = tmp_path / "run"
    train(RunConfig(task="fourroom", agent="hdqn", seed=3, steps=1500, checkpoint_steps=500), out, progress=False,
          stop_at=500)
    before = _rows(out)
    for other in (RunConfig(task="keydoor", agent="hdqn"), RunConfig(task="fourroom", agent="hdqn", seed=4),
                  RunConfig(task="fourroom", agent="hdqn", overrides=["loop.option_steps=5"])):
        with pytest.raises(RunError, match="continues the run as it was recorded"):
            train(other, out, resume=True, progress=False)
    assert _rows(out) == before
    summary = train(RunConfig(task="fourroom", agent="hdqn"), out, resume=True, progress=False)
    assert summary["finished"] and yaml.safe_load((out / "config.yaml").read_text())["seed"] == 3
