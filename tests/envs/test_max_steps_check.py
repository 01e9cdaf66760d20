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


def test_a_maze_too_large_to_plan_exactly_is_checked_trained_and_evaluated_without_an_optimum(tmp_path, capsys,
                                                                                                 monkeypatch):
    """A large maze with drop passes the reachability check (which leaves drop out first) but its full
    search passes the planner's cap of states: tasks, train and evaluate go on without an optimum rather
    than stop on 'unexpected RuntimeError'."""
    from hubsgo_ppl.envs.minigrid import bfs

    def too_many(*args, **kwargs):
        raise RuntimeError("m.yaml: BFS visited over 2000000 states; the maze is too large to plan exactly")

    monkeypatch.setattr(bfs, "optimal_steps_range", too_many)
    monkeypatch.setattr(bfs, "optimal_return", too_many)
    path = _maze(tmp_path, 100)
    assert main(["tasks", path]) == 0
    assert "the shortest solution has too many states to find exactly" in capsys.readouterr().out
    run = str(tmp_path / "r")
    assert main(["train", path, "--graph", "independent", "--steps", "10", "--out", run, "--no-progress"]) == 0
    assert main(["evaluate", run, "--episodes", "2"]) == 0
    assert "optimal" not in capsys.readouterr().out.splitlines()[-1]
