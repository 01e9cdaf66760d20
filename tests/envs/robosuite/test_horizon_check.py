"""An arm task whose horizon is shorter than one option of the hierarchical agents (the control steps
the low level is given for one sub-goal) is named by `hubsgo tasks` and `hubsgo train`, as a maze whose
max_steps is below its shortest solution is (from the catalogue, or from --set env.horizon)."""

import yaml

from hubsgo_ppl.cli import main


def _stack_one(tmp_path, horizon):
    path = tmp_path / "stack_one.yaml"
    path.write_text(yaml.safe_dump({
        "task": "stack_one", "family": "robosuite",
        "options": {"env_class": "StackCubes", "cubes": ["yellow"], "pads": ["a", "b"], "horizon": horizon},
        "subgoals": [{"name": "y_on_a", "kind": "place_on", "args": {"object": "yellow", "onto": "a"}},
                     {"name": "y_on_b", "kind": "place_on", "args": {"object": "yellow", "onto": "b"}}]}))
    return str(path)


def test_a_horizon_shorter_than_one_option_is_warned(tmp_path, capsys):
    path = _stack_one(tmp_path, 7)
    assert main(["tasks", path]) == 0
    assert ("    horizon: WARNING: horizon 7 is shorter than one option (loop.option_steps 60 control steps"
            in capsys.readouterr().out)
    assert main(["train", path, "--graph", "independent", "--steps", "14", "--out", str(tmp_path / "r"),
                 "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "hubsgo: warning: " in err and "horizon 7 is shorter than one option" in err, err


def test_a_horizon_set_below_one_option_is_warned_and_an_ample_one_is_not(tmp_path, capsys):
    path = _stack_one(tmp_path, 100)
    assert main(["tasks", path]) == 0
    assert "WARNING" not in capsys.readouterr().out
    assert main(["train", path, "--agent", "hdqn", "--low-level", "learned", "--steps", "30", "--set",
                 "env.horizon=30", "--out", str(tmp_path / "r"), "--no-progress"]) == 0
    assert "horizon 30 is shorter than one option (loop.option_steps 120 control steps" in capsys.readouterr().err
