"""train_env on a Gymnasium env of one's own (hubsgo_ppl/experiments/own_env.py, examples/own_env.py): the
run folder it writes is read by every `hubsgo` command, and resumes as if never interrupted."""

import importlib
import json
from pathlib import Path

import pytest
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments import RunError, train_env
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.specs import SpecError

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]"]


@pytest.fixture
def examples(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    return importlib.import_module("own_env"), importlib.import_module("corridor_env")


def _rows(path):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in read_csv_rows(path)]


def test_the_example_trains_and_every_command_reads_its_run(tmp_path, examples, capsys):
    own_env, _ = examples
    out = tmp_path / "corridor"
    summary = own_env.main(["--steps", "1200", "--out", str(out), *[a for s in TINY for a in ("--set", s)]])
    printed = capsys.readouterr().out
    assert "G*: [" in printed
    task = yaml.safe_load((out / "task.yaml").read_text())
    assert task["family"] == "gym" and task["options"]["entry_point"] == "corridor_env:make_corridor"
    assert [s["args"].get("fn") for s in task["subgoals"]] == ["corridor_env:switch_on"] * 2 + [None]
    config = yaml.safe_load((out / "config.yaml").read_text())
    assert config["task_ref"] == str((out / "task.yaml").resolve()) and config["hyper"]["low"]["hidden"] == [32]

    assert main(["subgoals", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "G* from 10,000 critic samples" in shown and "switch_a" in shown
    assert main(["evaluate", str(out), "--episodes", "3"]) == 0
    result = json.loads((out / "eval.json").read_text())
    assert result["episodes"] == 3 and len(result["returns"]) == 3 and result["task"] == "corridor"
    assert main(["review", str(out)]) == 0
    review = json.loads((out / "review" / "review.json").read_text())
    assert review["env_steps"] == summary["env_steps"] >= 1200 and (out / "review" / "suggested_spec.yaml").is_file()
    assert main(["revise", str(out), "--model", str(out / "review" / "suggested_spec.yaml"), "--no-train"]) == 0
    assert main(["render", str(out), "--out", str(tmp_path / "ep.gif")]) == 0
    from PIL import Image

    gif = Image.open(tmp_path / "ep.gif")
    assert gif.n_frames >= 2 and gif.width == 16 * 13       # the corridor's own frames, 13 cells of 16 pixels
    assert main(["diagnose", str(out), "--chains", "2", "--draws", "10"]) == 0
    before = len(read_csv_rows(out / "metrics.csv"))
    capsys.readouterr()
    assert main(["train", str(out / "task.yaml"), "--out", str(out), "--resume", "--steps", "1500",
                 "--no-progress"]) == 0
    rows = read_csv_rows(out / "metrics.csv")
    assert len(rows) > before and int(rows[-1]["env_steps"]) >= 1500


def test_a_resumed_run_logs_what_an_uninterrupted_one_does(tmp_path, examples):
    _, corridor = examples
    goals = {"switch_a": {"fn": corridor.switch_on, "which": "a"}, "goal": {"kind": "goal"}}
    spec = {"name": "corridor", "subgoals": ["switch_a", "goal"], "edges": [["switch_a", "goal", "positive"]]}
    kwargs = dict(model=spec, steps=1000, seed=4, max_episode_steps=40, overrides=TINY, task="corridor")
    train_env(corridor.make_corridor, goals, tmp_path / "whole", **kwargs)
    paused = train_env(corridor.make_corridor, goals, tmp_path / "parts", stop_at=450, **kwargs)
    assert not paused["finished"] and (tmp_path / "parts" / "checkpoint.pt").is_file()
    resumed = train_env(corridor.make_corridor, goals, tmp_path / "parts", resume=True, **kwargs)
    assert resumed["finished"]
    whole = _rows(tmp_path / "whole" / "metrics.csv")
    assert len(whole) > 10 and _rows(tmp_path / "parts" / "metrics.csv") == whole
    ranking = [json.loads((tmp_path / d / "subgoals.json").read_text())["ranking"] for d in ("whole", "parts")]
    assert ranking[0] == ranking[1]


def test_hdqn_and_a_flat_baseline_train_on_a_registered_id(tmp_path):
    goals = {"goal": {"kind": "goal"}}
    for agent in ("hdqn", "dqn"):
        summary = train_env("Blackjack-v1", goals, tmp_path / agent, agent=agent, steps=300, overrides=TINY
                            if agent == "hdqn" else ["dqn.learning_starts=50"])
        assert summary["finished"] and summary["env_steps"] >= 300
        assert yaml.safe_load((tmp_path / agent / "task.yaml").read_text())["options"] == {"gym_id": "Blackjack-v1"}
    assert main(["evaluate", str(tmp_path / "dqn"), "--episodes", "2"]) == 0


def test_a_lambda_trains_and_a_command_in_another_process_says_it_cannot_rebuild_it(tmp_path, examples, capsys,
                                                                                    monkeypatch):
    _, corridor = examples
    out = tmp_path / "run"
    train_env(corridor.make_corridor, {"far_left": lambda env, obs, info: env.pos == 0, "goal": {"kind": "goal"}}, out,
              agent="hdqn", steps=200, overrides=TINY)
    err = capsys.readouterr().err
    assert "sub-goal 'far_left' (<local>:lambda#" in err and "cannot rebuild" in err
    assert main(["evaluate", str(out), "--episodes", "1"]) == 0         # this process holds the lambda
    monkeypatch.setattr("hubsgo_ppl.envs.gym_task._LOCAL", {})          # another process does not
    capsys.readouterr()
    assert main(["evaluate", str(out), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "define it at the top level of an importable module" in err[0]


def test_bad_calls_are_refused_before_anything_is_written(tmp_path, examples):
    _, corridor = examples
    goals = {"goal": {"kind": "goal"}}
    with pytest.raises(RunError, match="agent 'hubsgo' needs model="):
        train_env(corridor.make_corridor, goals, tmp_path / "a")
    with pytest.raises(SpecError, match="unknown kind 'carrying'"):
        train_env(corridor.make_corridor, {"key": {"kind": "carrying"}}, tmp_path / "b", agent="hdqn")
    with pytest.raises(SpecError, match="sub-goal name"):
        train_env(corridor.make_corridor, {"a b": {"kind": "goal"}}, tmp_path / "c", agent="hdqn")
    assert not any((tmp_path / d).exists() for d in "abc")
    out = tmp_path / "d"
    train_env(corridor.make_corridor, goals, out, agent="hdqn", steps=100, overrides=TINY)
    kept = (out / "task.yaml").read_text()
    with pytest.raises(RunError, match="was trained with another task.yaml"):
        train_env(corridor.make_corridor, goals, out, agent="hdqn", steps=100, overrides=TINY, max_episode_steps=9)
    assert (out / "task.yaml").read_text() == kept


def _corridor_without_render_mode():
    import corridor_env

    return corridor_env.make_corridor()


def test_render_of_an_env_that_takes_no_render_mode_says_so(tmp_path, examples, capsys):
    out = tmp_path / "plain"
    train_env(_corridor_without_render_mode, {"goal": {"kind": "goal"}}, out=out, agent="hdqn", steps=200,
              max_episode_steps=30, overrides=TINY)
    capsys.readouterr()
    assert main(["render", str(out), "--out", str(tmp_path / "ep.gif")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "takes no render_mode argument" in err[0] and "options.kwargs" not in err[0], err
