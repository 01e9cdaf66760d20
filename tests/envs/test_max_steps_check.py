"""A maze whose max_steps truncates every episode before the shortest solution reaches the goal is named
by `hubsgo tasks` and `hubsgo train` (from the catalogue, or from --set env.max_steps)."""

import yaml

from hubsgo_ppl.cli import main


def _maze(tmp_path, max_steps):
    (tmp_path / "m.txt").write_text("#######\n#A....#\n#....G#\n#######\n")
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "task": "m", "family": "minigrid", "options": {"layout": "m.txt", "max_steps": max_steps},
        "subgoals": [{"name": "goal", "kind": "goal"}]}))
    return str(tmp_path / "m.yaml")


def test_a_max_steps_below_the_shortest_solution_is_warned(tmp_path, capsys):
    path = _maze(tmp_path, 3)
    assert main(["tasks", path]) == 0
    assert "WARNING: max_steps 3 is below the shortest solution" in capsys.readouterr().out
    assert main(["train", path, "--graph", "independent", "--steps", "10", "--out", str(tmp_path / "r"),
                 "--no-progress"]) == 0
    assert "warning: " in capsys.readouterr().err


def test_a_max_steps_set_below_the_shortest_solution_is_warned_and_an_ample_one_is_not(tmp_path, capsys):
    path = _maze(tmp_path, 100)
    assert main(["tasks", path]) == 0
    assert "WARNING" not in capsys.readouterr().out
    assert main(["train", path, "--graph", "independent", "--steps", "10", "--set", "env.max_steps=2", "--out",
                 str(tmp_path / "r"), "--no-progress"]) == 0
    assert "max_steps 2 is below the shortest solution" in capsys.readouterr().err
