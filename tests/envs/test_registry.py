"""Task registry: explicit, idempotent registration; clear errors; user catalogues by path."""

from __future__ import annotations

import textwrap

import gymnasium as gym
import numpy as np
import pytest

import hubsgo_ppl.envs as T
from hubsgo_ppl.envs import UnknownTaskError
from hubsgo_ppl.envs.minigrid import MazeEnv, bfs
from hubsgo_ppl.specs import SpecError

BUILTIN = {"keydoor": "hubsgo/KeyDoor-v0", "fourroom": "hubsgo/FourRoom-v0",
           "keydoor_incorrect": "hubsgo/KeyDoorIncorrect-v0",
           "fourroom_incorrect": "hubsgo/FourRoomIncorrect-v0"}


def test_builtin_task_names_and_ids():
    found = {n: t.env_id for n, t in T.tasks().items() if t.family == "minigrid"}
    assert BUILTIN.items() <= found.items()


def test_register_is_idempotent_and_gym_make_works():
    ids = T.register()
    n = len(gym.registry)
    assert T.register() == ids and len(gym.registry) == n
    assert set(BUILTIN.values()) <= set(ids)
    for task, env_id in BUILTIN.items():
        env = gym.make(env_id)
        assert isinstance(env.unwrapped, MazeEnv)
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs) and info["subgoals"].shape == (
            len(T.get_task(task).catalogue.subgoals),)
        env.close()


def test_gym_make_passes_kwargs():
    T.register()
    env = gym.make("hubsgo/KeyDoor-v0", obs_mode="image", max_steps=77)
    assert env.observation_space.shape == (13 * 13 * 3,) and env.unwrapped.max_steps == 77


def test_unknown_task_lists_the_known_ones():
    with pytest.raises(UnknownTaskError) as exc:
        T.make("keydor")
    msg = str(exc.value)
    assert "unknown task 'keydor'" in msg
    for name in BUILTIN:
        assert name in msg
    assert isinstance(exc.value, SpecError)


@pytest.mark.parametrize("name, expected", [
    ("hubsgo/KeyDoor-v0", "is the Gymnasium id of task 'keydoor': pass keydoor"),
    ("MiniGrid-Unlock-v0", "'MiniGrid-Unlock-v0' is a Gymnasium id, not a task: write a catalogue"),
    ("MiniGrid-DoorKey-8x8-v0", "task 'doorkey_8x8' wraps it with a catalogue of sub-goals: pass doorkey_8x8"),
    ("ALE/Pong-v5", "family gym for any other, docs/own_env.md"),
    ("Foo-v0", "unknown task 'Foo-v0', and no Gymnasium id of that name is registered; use one of: annex"),
])
def test_a_gymnasium_id_in_place_of_a_task_says_what_to_pass(name, expected):
    with pytest.raises(UnknownTaskError) as exc:
        T.get_task(name)
    assert expected in str(exc.value) and "\n" not in str(exc.value)
    assert ("use one of" in str(exc.value)) == (name == "Foo-v0")


def test_user_catalogue_in_a_temp_folder(tmp_path):
    (tmp_path / "corridor.txt").write_text("; a user maze\n#########\n#A..a...#\n#....#.G#\n#########\n")
    (tmp_path / "corridor.yaml").write_text(textwrap.dedent("""\
        # a maze added without Python
        task: corridor
        family: minigrid
        options:
          layout: corridor.txt
          legend: {a: {type: ball, color: purple}}
          max_steps: 60
        subgoals:
          - {name: ball, kind: carrying, args: {type: ball, color: purple}}
          - {name: middle, kind: at, args: {cell: [4, 2]}}
          - {name: goal, kind: goal}
        """))
    env = T.make(tmp_path / "corridor.yaml", seed=3)
    u = env.unwrapped
    assert u.subgoal_names == ["ball", "middle", "goal"] and u.max_steps == 60
    assert T.get_task(str(tmp_path / "corridor.yaml")).env_id == "hubsgo/Corridor-v0"
    assert list(T.tasks(tmp_path)) == ["corridor"]
    # one-hot x (9) + y (4) + direction (4) + carried (nothing, purple ball); no doors
    assert env.observation_space.shape == (9 + 4 + 4 + 2,)
    # the ball blocks the only way through, so the optimal plan picks it up
    assert u.action_names[bfs.plan(env, "ball")[-1]] == "pickup"
    total = sum(env.step(a)[1] for a in bfs.plan(env))
    assert total == pytest.approx(bfs.optimal_return(tmp_path / "corridor.yaml"))
    assert np.isclose(total, 1 - 0.9 * bfs.optimal_steps(tmp_path / "corridor.yaml") / 60)


def test_missing_user_catalogue():
    with pytest.raises(SpecError, match="no such task catalogue file"):
        T.make("nowhere/maze.yaml")


def test_a_directory_given_as_a_catalogue_or_a_layout_is_named_as_one(tmp_path):
    (tmp_path / "maze.yaml").mkdir()
    with pytest.raises(SpecError, match="maze.yaml: a directory, not a task catalogue file"):
        T.make(tmp_path / "maze.yaml")
    (tmp_path / "rooms.txt").mkdir()
    (tmp_path / "rooms.yaml").write_text("task: rooms\nfamily: minigrid\noptions: {layout: rooms.txt}\n"
                                         "subgoals:\n  - {name: goal, kind: goal}\n")
    with pytest.raises(SpecError, match="rooms.txt' is a directory"):
        T.make(tmp_path / "rooms.yaml")


@pytest.mark.parametrize("task", sorted(BUILTIN))
def test_critic_specs_match_the_catalogue(task):
    """models/<task>-{specific,fully_connected,independent}.yaml list the catalogue's sub-goals in
    order, and their edges name real sub-goals (the critic's loader checks the same)."""
    import yaml

    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.resources import models_dir

    names = T.get_task(task).catalogue.names
    signs = {"positive": 1, "negative": -1, "unknown": 0}
    specs = {g: yaml.safe_load((models_dir() / f"{task}-{g}.yaml").read_text())
             for g in ("specific", "fully_connected", "independent")}
    for graph, spec in specs.items():
        assert spec["name"] == f"{task}-{graph}" and spec["task"] == task and spec["graph"] == graph
        assert spec["subgoals"] == names
        g = SubgoalGraph(names, [(u, v, signs[s]) for u, v, s in spec["edges"]]).preset(graph)
        assert g.n == len(names)
    assert specs["independent"]["edges"] == []
    # the paper's fully connected setting: every pair coupled, no sign given (no knowledge beyond the list)
    assert specs["fully_connected"]["edges"] == []
    full = SubgoalGraph(names, []).preset("fully_connected")
    assert full.num_edges == len(names) * (len(names) - 1) // 2 and not full.edge_sign.any()
    assert {k: specs["fully_connected"][k] for k in ("prior", "likelihood", "inference")} == {
        k: specs["specific"][k] for k in ("prior", "likelihood", "inference")}
    touched = {n for e in specs["specific"]["edges"] for n in e[:2]}
    assert touched == {n for n in names if not n.startswith("corner_")}


def _shipped_specs() -> list[str]:
    from hubsgo_ppl.resources import models_dir

    return sorted(p.stem for p in models_dir().glob("*.yaml") if p.stem != "example-specific")   # no task: generic


@pytest.mark.parametrize("name", _shipped_specs())
def test_every_shipped_spec_resolves_for_its_task(name):
    """Each file under models/ is named after itself, names a task that exists, and resolves for it as
    `hubsgo train TASK --model NAME` would (sub-goals in the catalogue, edges between them, valid prior,
    likelihood and inference)."""
    import yaml

    from hubsgo_ppl.experiments.run import RunConfig, resolve
    from hubsgo_ppl.resources import models_dir

    spec = yaml.safe_load((models_dir() / f"{name}.yaml").read_text())
    assert spec["name"] == name
    resolved = resolve(RunConfig(task=spec["task"], agent="hubsgo", model=name))
    names = T.get_task(spec["task"]).catalogue.names
    assert resolved["model"] == name and set(resolved["model_spec"]["subgoals"]) <= set(names)
