"""Catalogues that name a registered MiniGrid id: the sub-goal kinds on hand-built grids, the env's
contract, the catalogue's refusals, and a tiny run on each shipped one."""

from __future__ import annotations

import textwrap
import warnings

import numpy as np
import pytest
from minigrid.core.grid import Grid
from minigrid.core.world_object import Ball, Box, Door, Goal, Key, Wall

from hubsgo_ppl.cli import main
from hubsgo_ppl.envs import make, tasks
from hubsgo_ppl.envs.check import check_env
from hubsgo_ppl.envs.minigrid.kinds import compile_kind, new_scene
from hubsgo_ppl.envs.minigrid.registered import RegisteredEnv, is_registered
from hubsgo_ppl.envs.subgoals import SubgoalDef
from hubsgo_ppl.specs import SpecError

REGISTERED = sorted(n for n, t in tasks().items() if t.family == "minigrid" and is_registered(t.catalogue))


def kind(kind: str, **args):
    return compile_kind(0, SubgoalDef(name="g", kind=kind, args=args), "<test>")


def two_rooms(door: Door, left: list | None = None, right: list | None = None) -> Grid:
    """A 9x5 grid: a wall at x=4 with ``door`` at (4, 2); objects (obj, (x, y)) placed by hand."""
    g = Grid(9, 5)
    g.wall_rect(0, 0, 9, 5)
    for y in range(5):
        g.set(4, y, Wall())
    g.set(4, 2, door)
    for obj, (x, y) in (left or []) + (right or []):
        g.set(x, y, obj)
    return g


def test_carrying_an_unnamed_colour_matches_any_key_and_aims_at_the_nearest():
    far, near = Key("red"), Key("blue")
    g = two_rooms(Door("yellow", is_locked=True), left=[(far, (1, 1)), (near, (3, 3))])
    s = new_scene(g, (2, 3))
    any_key, red_key = kind("carrying", type="key"), kind("carrying", type="key", color="red")
    ball = kind("carrying", type="ball")
    assert not any_key.holds(s) and any_key.target(s) == (3, 3)       # distance 1 beats distance 3
    assert red_key.target(s) == (1, 1)
    assert ball.target(s) == (2, 3)                                   # nothing to reach: the agent's cell
    g.set(3, 3, None)
    s.reread(g, near)
    assert any_key.holds(s) and not red_key.holds(s) and not ball.holds(s)
    assert any_key.target(s) == (2, 3)                                # carried: where the agent is


def test_door_open_locked_means_locked_at_reset_and_route_counts_doors_to_the_goal():
    locked, plain = Door("yellow", is_locked=True), Door("green")
    g = Grid(13, 5)
    g.wall_rect(0, 0, 13, 5)
    for y in range(5):
        g.set(4, y, Wall())
        g.set(8, y, Wall())
    g.set(4, 2, plain)
    g.set(8, 2, locked)
    g.set(11, 2, Goal())
    s = new_scene(g, (1, 2))
    was_locked, unlocked, first, second, third = (kind("door_open", locked=True), kind("door_open", locked=False),
                                                 kind("door_open", route=1), kind("door_open", route=2),
                                                 kind("door_open", route=3))
    assert s.route == (id(plain), id(locked))
    assert was_locked.target(s) == (8, 2) and first.target(s) == (4, 2) and second.target(s) == (8, 2)
    assert not any(k.holds(s) for k in (was_locked, unlocked, first, second, third))
    plain.is_open = True
    assert unlocked.holds(s) and first.holds(s) and not was_locked.holds(s) and not second.holds(s)
    locked.is_locked, locked.is_open = False, True                      # unlocked by its key: still "locked: true"
    assert was_locked.holds(s) and second.holds(s) and not third.holds(s)
    assert kind("door_open").holds(s)


def test_box_open_holds_once_the_box_is_gone_and_not_when_it_is_carried():
    box = Box("purple")
    g = two_rooms(Door("yellow"), right=[(box, (6, 3))])
    s = new_scene(g, (1, 1))
    opened, purple, red = kind("box_open"), kind("box_open", color="purple"), kind("box_open", color="red")
    assert not opened.holds(s) and opened.target(s) == (6, 3)
    g.set(6, 3, None)
    s.reread(g, box)                       # picked up
    assert not opened.holds(s) and opened.target(s) == (1, 1)
    s.reread(g, None)                      # toggled away (MiniGrid puts its contents, here nothing)
    assert opened.holds(s) and purple.holds(s) and not red.holds(s)


def test_cleared_is_false_while_an_object_lies_next_to_a_door():
    ball, key = Ball("green"), Key("yellow")
    g = two_rooms(Door("yellow", is_locked=True), left=[(ball, (3, 2)), (key, (1, 1))])
    s = new_scene(g, (1, 3))
    balls, anything = kind("cleared", type="ball"), kind("cleared")
    assert not balls.holds(s) and balls.target(s) == (3, 2)
    g.set(3, 2, None)
    g.set(2, 3, ball)                       # moved one cell away from the doorway
    s.reread(g, None)
    assert balls.holds(s) and anything.holds(s) and balls.target(s) == (1, 3)
    g.set(5, 2, Key("red"))                  # a key on the other side of the door blocks it too
    s.reread(g, None)
    assert balls.holds(s) and not anything.holds(s) and anything.target(s) == (5, 2)


def test_in_room_splits_rooms_at_doors_and_at_one_cell_gaps_in_a_wall():
    g = two_rooms(Door("yellow", is_open=True), right=[(Goal(), (7, 3))])
    goal_room = kind("in_room", type="goal")
    for cell, inside in [((1, 1), False), ((4, 2), False), ((5, 2), True), ((7, 1), True)]:
        s = new_scene(g, cell)
        assert goal_room.holds(s) == inside, cell
        assert goal_room.target(s) == (7, 3)
    g.set(4, 2, None)                        # a gap instead of the door: still two rooms
    assert not goal_room.holds(new_scene(g, (3, 2))) and goal_room.holds(new_scene(g, (5, 2)))
    assert new_scene(g, (1, 1)).rooms[4, 2] == -1


def test_at_a_type_is_on_or_next_to_it_and_at_a_cell_is_on_it():
    door = Door("blue")
    g = two_rooms(door)
    near_door, blue, red, spot = (kind("at", type="door"), kind("at", type="door", color="blue"),
                                  kind("at", type="door", color="red"), kind("at", cell=[2, 2]))
    s = new_scene(g, (3, 2))
    assert near_door.holds(s) and blue.holds(s) and not red.holds(s) and near_door.target(s) == (4, 2)
    s = new_scene(g, (2, 2))
    assert not near_door.holds(s) and spot.holds(s) and spot.target(s) == (2, 2)


def test_goal_holds_on_success_and_aims_at_the_goal_or_else_the_mission_object():
    g = two_rooms(Door("yellow"), right=[(Goal(), (7, 3))])
    s = new_scene(g, (1, 1))
    goal = kind("goal")
    assert not goal.holds(s) and goal.target(s) == (7, 3)
    s.success = True
    assert goal.holds(s)
    box = Box("red")
    s = new_scene(two_rooms(Door("yellow"), right=[(box, (6, 1))]), (1, 1), mission_obj=box)
    assert goal.target(s) == (6, 1)
    assert goal.target(new_scene(two_rooms(Door("yellow")), (1, 1), mission_cell=np.array([3, 1]))) == (3, 1)
    assert goal.target(new_scene(two_rooms(Door("yellow")), (1, 1))) == (1, 1)


@pytest.mark.parametrize("sg, fragment", [
    ({"kind": "fly"}, "unknown kind 'fly'"),
    ({"kind": "carrying", "args": {"type": "door"}}, "subgoals[0] (g).args.type"),
    ({"kind": "carrying", "args": {"color": "pink"}}, "unknown colour 'pink'"),
    ({"kind": "door_open", "args": {"route": 0}}, "counts doors from 1"),
    ({"kind": "door_open", "args": {"cell": [1, 2]}}, "rather than by cell"),
    ({"kind": "at", "args": {}}, "give either cell"),
    ({"kind": "in_room", "args": {}}, "subgoals[0] (g).args.type"),
    ({"kind": "cleared", "args": {"type": "ball", "locked": True}}, "locked applies to doors only"),
])
def test_bad_kinds_are_named_with_their_key(sg, fragment):
    with pytest.raises(SpecError) as err:
        compile_kind(0, SubgoalDef(name="g", **sg), "cat.yaml")
    assert fragment in str(err.value) and "\n" not in str(err.value)


def _catalogue(tmp_path, options: str, name: str = "mine") -> str:
    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(f"""\
        task: {name}
        family: minigrid
        options: {options}
        subgoals:
          - {{name: key, kind: carrying, args: {{type: key}}}}
          - {{name: goal, kind: goal}}
        """))
    return str(path)


@pytest.mark.parametrize("options, fragment", [
    ("{gym_id: MiniGrid-DoorKey-5x5-v0, layout: keydoor.txt}", "give either layout"),
    ("{gym_id: MiniGrid-NoSuchThing-v0}", "'MiniGrid-NoSuchThing-v0' is not a registered Gymnasium id"),
    ("{gym_id: CartPole-v1}", "'CartPole-v1' is not a MiniGrid environment"),
    ("{gym_id: MiniGrid-DoorKey-5x5-v0, obs_mode: symbolic}", "options.obs_mode"),
    ("{gym_id: MiniGrid-DoorKey-5x5-v0, actions: [left, jump]}", "unknown action"),
])
def test_bad_registered_catalogues_exit_2_with_one_line(tmp_path, capsys, options, fragment):
    cat = _catalogue(tmp_path, options)
    assert main(["train", cat, "--agent", "hdqn", "--steps", "10", "--out", str(tmp_path / "run"),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err
    assert not (tmp_path / "run" / "checkpoint.pt").exists()


def test_a_registered_env_meets_the_contract_and_regenerates_its_layout(tmp_path):
    env = make(_catalogue(tmp_path, "{gym_id: MiniGrid-DoorKey-5x5-v0}"))
    assert isinstance(env, RegisteredEnv) and env.subgoal_names == ["key", "goal"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert check_env(env, steps=30) == []
    obs0, info = env.reset(seed=0)
    assert obs0.shape == env.observation_space.shape and obs0.dtype == np.float32
    assert info["subgoals"].tolist() == [False, False] and info["is_success"] is False
    keys = set()
    for seed in range(6):
        env.reset(seed=seed)
        keys.add(env.subgoal_target(0))
    assert len(keys) > 1                                       # the key moves from layout to layout
    a, _ = env.reset(seed=3)
    b, _ = make(_catalogue(tmp_path, "{gym_id: MiniGrid-DoorKey-5x5-v0}")).reset(seed=3)
    assert np.array_equal(a, b)


def test_the_egocentric_potential_is_minus_the_distance_to_each_target(tmp_path):
    import torch

    env = make(_catalogue(tmp_path, "{gym_id: MiniGrid-DoorKey-5x5-v0}"))
    obs, _ = env.reset(seed=1)
    phi = env.subgoal_potential()(torch.as_tensor(obs))
    ax, ay = env.agent_pos
    want = [-(abs(tx - ax) + abs(ty - ay)) / (env.width + env.height)
            for tx, ty in (env.subgoal_target(i) for i in range(2))]
    assert phi.tolist() == pytest.approx(want)


def test_the_shipped_registered_catalogues():
    assert {"doorkey_8x8", "doorkey_16x16", "keycorridor_s3r3", "unlockpickup", "blockedunlockpickup",
            "multiroom_n4_s5", "lockedroom", "fourrooms"} <= set(REGISTERED)


@pytest.mark.parametrize("task", REGISTERED)
def test_tiny_run_on_each_shipped_registered_catalogue(task, tmp_path):
    run = tmp_path / task
    # episodes end at 60 steps, so that the run stops near its budget (DoorKey-16x16's own limit is 2,560)
    assert main(["train", task, "--steps", "300", "--set", "env.max_steps=60", "--out", str(run),
                 "--no-progress"]) == 0
    assert (run / "checkpoint.pt").is_file() and (run / "subgoals.json").is_file()


def test_a_subset_of_the_subgoals_keeps_the_observation_and_the_targets():
    from hubsgo_ppl.envs.subset import make_subset

    full, sub = make("unlockpickup"), make_subset("unlockpickup", ["key", "door", "goal"])
    a, info_a = full.reset(seed=4)
    b, info_b = sub.reset(seed=4)
    assert np.array_equal(a, b) and sub.subgoal_names == ["key", "door", "goal"]
    assert info_b["subgoals"].tolist() == info_a["subgoals"][[0, 1, 4]].tolist()
    assert [sub.subgoal_target(i) for i in range(3)] == [full.subgoal_target(i) for i in (0, 1, 4)]


def test_a_run_on_a_registered_catalogue_resumes_and_is_read(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "fourrooms", "--steps", "200", "--out", str(run), "--no-progress"]) == 0
    assert main(["train", "fourrooms", "--steps", "400", "--out", str(run), "--resume", "--no-progress"]) == 0
    assert main(["evaluate", str(run), "--episodes", "2"]) == 0
    assert main(["subgoals", str(run)]) == 0
    out = capsys.readouterr().out
    assert "goal_room" in out and "optimal" not in out
    assert main(["tasks", "fourrooms"]) == 0           # no layout to search: no reachability line
    out = capsys.readouterr().out
    assert "MiniGrid's FourRooms" in out and "reachability" not in out and "valid for this task" in out


@pytest.mark.parametrize("gym_id", ["MiniGrid-ObstructedMaze-1Dlhb-v0", "MiniGrid-RedBlueDoors-6x6-v0",
                                    "MiniGrid-LavaGapS5-v0", "MiniGrid-Dynamic-Obstacles-5x5-v0",
                                    "MiniGrid-GoToDoor-5x5-v0", "BabyAI-KeyCorridorS3R1-v0"])
def test_every_kind_runs_on_environments_no_catalogue_here_was_written_for(tmp_path, gym_id):
    lines = ["{name: key, kind: carrying, args: {type: key}}", "{name: door, kind: door_open, args: {locked: true}}",
             "{name: first, kind: door_open, args: {route: 1}}", "{name: box, kind: box_open}",
             "{name: clear, kind: cleared}", "{name: room, kind: in_room, args: {type: goal}}",
             "{name: near, kind: at, args: {type: door}}", "{name: goal, kind: goal}"]

    def catalogue(subgoals: list[str]) -> str:
        path = tmp_path / "any.yaml"
        path.write_text(f"task: any\nfamily: minigrid\noptions: {{gym_id: {gym_id}, actions: [left, right, "
                        "forward, pickup, drop, toggle, done]}\nsubgoals:\n" + "".join(f"  - {x}\n" for x in subgoals))
        return str(path)

    kept = []
    for line in lines:                 # a kind whose objects the env never has is refused in one line
        try:
            make(catalogue([line]))
            kept.append(line)
        except SpecError as err:
            assert "has none in 8 seeded layouts" in str(err) and "\n" not in str(err)
    assert len(kept) >= 3
    env = make(catalogue(kept))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert check_env(env, steps=40) == []
    rng = np.random.default_rng(0)
    for seed in range(3):
        obs, _ = env.reset(seed=seed)
        for _ in range(40):
            obs, _, terminated, truncated, info = env.step(int(rng.integers(env.action_space.n)))
            assert obs.shape == env.observation_space.shape and np.abs(obs).max() <= 1.0
            for i in range(len(kept)):
                x, y = env.subgoal_target(i)
                assert 0 <= x < env.width and 0 <= y < env.height
            if terminated or truncated:
                break


def test_a_route_door_past_the_doors_of_every_seeded_layout_is_warned_of(tmp_path, capsys):
    path = tmp_path / "rooms.yaml"
    path.write_text(textwrap.dedent("""\
        task: rooms
        family: minigrid
        options: {gym_id: MiniGrid-MultiRoom-N2-S4-v0, actions: [left, right, forward, toggle]}
        subgoals:
          - {name: door_1, kind: door_open, args: {route: 1}}
          - {name: door_2, kind: door_open, args: {route: 2}}
          - {name: goal, kind: goal}
        """))
    RegisteredEnv(str(path)).close()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "(door_2)" in err[0] and "number 2 on the way to the goal" in err[0], err


def test_an_at_cell_that_is_a_wall_in_every_seeded_layout_is_warned_of(tmp_path, capsys):
    path = tmp_path / "shift.yaml"
    path.write_text(textwrap.dedent("""\
        task: shift
        family: minigrid
        options: {gym_id: MiniGrid-DistShift1-v0, actions: [left, right, forward]}
        subgoals:
          - {name: border, kind: at, args: {cell: [1, 6]}}
          - {name: floor, kind: at, args: {cell: [1, 5]}}
          - {name: goal, kind: goal}
        """))
    RegisteredEnv(str(path)).close()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "(border).args.cell: [1, 6] is a wall in all 8 seeded layouts" in err[0], err
