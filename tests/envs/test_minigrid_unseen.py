"""Kinds for MiniGrid tasks beyond the shipped catalogues, and catalogues written without this project's
ones in view (tests/fixtures/minigrid_*.yaml): each checks and trains for a few hundred steps."""

from __future__ import annotations

import warnings
from pathlib import Path
from types import SimpleNamespace

import pytest
from minigrid.core.grid import Grid
from minigrid.core.world_object import Ball, Box, Door, Goal, Key, Lava, Wall

from hubsgo_ppl.cli import main
from hubsgo_ppl.envs import make
from hubsgo_ppl.envs.minigrid.kinds import compile_kind, mission_named, new_scene
from hubsgo_ppl.envs.minigrid.reach import goal_reachable, missing_for_goal
from hubsgo_ppl.envs.subgoals import SubgoalDef
from hubsgo_ppl.specs import SpecError

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures"


def kind(kind: str, **args):
    return compile_kind(0, SubgoalDef(name="g", kind=kind, args=args), "<test>")


def room(*objects) -> Grid:
    """A 7x5 grid walled round, with a wall at x=4 and a door at (4, 2); objects (obj, (x, y))."""
    g = Grid(7, 5)
    g.wall_rect(0, 0, 7, 5)
    for y in range(5):
        g.set(4, y, Wall())
    for obj, (x, y) in objects:
        g.set(x, y, obj)
    return g


def test_facing_holds_only_for_the_object_in_front_of_the_agent():
    red, blue = Ball("red"), Ball("blue")
    g = room((red, (2, 1)), (blue, (2, 3)), (Door("green"), (4, 2)))
    red_ball, any_ball, door = kind("facing", type="ball", color="red"), kind("facing", type="ball"), \
        kind("facing", type="door")
    s = new_scene(g, (2, 2), front=(2, 1))                      # facing up, at the red ball
    assert red_ball.holds(s) and any_ball.holds(s) and not door.holds(s)
    s.front = (2, 3)                                            # turned round: the blue ball
    assert not red_ball.holds(s) and any_ball.holds(s)
    s.front = (3, 2)                                            # next to the door's cell, not facing it
    assert not door.holds(s) and door.target(s) == (4, 2) and red_ball.target(s) == (2, 1)
    s.agent, s.front = (3, 2), (4, 2)
    assert door.holds(s)


def test_placed_near_counts_diagonals_ignores_the_carried_object_and_aims_at_the_anchor():
    key, box = Key("blue"), Box("purple")
    g = room((key, (1, 1)), (box, (3, 3)))
    placed = kind("placed_near", type="key", near={"type": "box", "color": "purple"})
    wrong = kind("placed_near", type="key", near={"type": "box", "color": "red"})
    s = new_scene(g, (2, 2))
    assert not placed.holds(s) and placed.target(s) == (1, 1)   # go and take the key
    g.set(1, 1, None)
    s.reread(g, key)                                            # carried: aim at the box
    assert not placed.holds(s) and placed.target(s) == (3, 3)
    g.set(2, 2, key)                                            # dropped diagonally next to the box
    s.reread(g, None)
    assert placed.holds(s) and not wrong.holds(s)
    g.set(2, 2, None)
    g.set(1, 2, key)                                            # two cells away
    s.reread(g, None)
    assert not placed.holds(s)
    same = kind("placed_near", type="box", near={"type": "box"})
    assert not same.holds(new_scene(room((Box("red"), (1, 1))), (2, 2)))   # an object is not near itself


def test_the_goal_aims_at_the_object_the_mission_names_last_where_nothing_else_says():
    assert mission_named("put the blue key near the purple box") == ("purple", "box")
    assert mission_named("open the door") == (None, "door")
    assert mission_named("get to the green goal square") is None
    red, blue = Ball("red"), Ball("blue")
    goal = kind("goal")
    g = room((red, (3, 1)), (blue, (1, 1)))
    assert goal.target(new_scene(g, (1, 2), mission="go to the red ball")) == (3, 1)   # not the nearer blue one
    assert goal.target(new_scene(g, (1, 2), mission="go to a ball")) == (1, 1)
    assert goal.target(new_scene(g, (1, 2), mission="go get a purple key")) == (1, 2)  # none: the agent's cell
    assert goal.target(new_scene(g, (1, 2), carrying=Key("purple"), mission="go get a purple key")) == (1, 2)


@pytest.mark.parametrize("sg, fragment", [
    ({"kind": "facing", "args": {}}, "subgoals[0] (g).args.type"),
    ({"kind": "placed_near", "args": {"type": "key"}}, "subgoals[0] (g).args.near"),
    ({"kind": "placed_near", "args": {"type": "door", "near": {"type": "box"}}}, "subgoals[0] (g).args.type"),
    ({"kind": "placed_near", "args": {"near": {"colour": "red"}}}, "colour"),
])
def test_bad_arguments_of_the_new_kinds_are_named(sg, fragment):
    with pytest.raises(SpecError) as err:
        compile_kind(0, SubgoalDef(name="g", **sg), "cat.yaml")
    assert fragment in str(err.value) and "\n" not in str(err.value)


def test_carrying_aims_at_the_box_that_holds_the_object_while_none_lies_on_the_floor():
    hidden, loose = Key("yellow"), Key("yellow")
    box = Box("green", contains=hidden)
    key = kind("carrying", type="key")
    g = room((box, (1, 3)))
    s = new_scene(g, (2, 1))
    assert key.target(s) == (1, 3) and kind("carrying", type="ball").target(s) == (2, 1)
    g.set(5, 3, loose)                                          # one on the floor: that one, though farther
    s.reread(g, None)
    assert key.target(s) == (5, 3)


@pytest.mark.parametrize("name", ["minigrid_obstructed_1dlh", "minigrid_redbluedoors", "minigrid_lavagap",
                                  "minigrid_putnear"])
def test_a_stranger_s_catalogue_checks_trains_and_is_read(name, tmp_path, capsys):
    cat, spec, run = FIXTURES / f"{name}.yaml", FIXTURES / f"{name}-spec.yaml", tmp_path / name
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["check-env", str(cat), "--steps", "30"]) == 0
        assert main(["train", str(cat), "--model", str(spec), "--steps", "300", "--set", "env.max_steps=60",
                     "--out", str(run), "--no-progress"]) == 0
        assert main(["subgoals", str(run)]) == 0
    assert (run / "checkpoint.pt").is_file()
    assert "marginals" in capsys.readouterr().out


@pytest.mark.parametrize("gym_id, subgoal, fragment", [
    ("MiniGrid-Empty-8x8-v0", "{name: key, kind: carrying, args: {type: key}}",
     "subgoals[0] (key).args: carrying needs a key, and MiniGrid-Empty-8x8-v0 has none"),
    ("MiniGrid-PutNear-6x6-N2-v0", "{name: p, kind: placed_near, args: {type: ball, near: {type: door}}}",
     "placed_near needs a door"),
    ("MiniGrid-Empty-5x5-v0", "{name: spot, kind: at, args: {cell: [9, 2]}}", "[9, 2] is outside"),
    ("MiniGrid-DoorKey-5x5-v0", "{name: key, kind: carrying, args: {colour: yellow}}", "args.colour: unknown key"),
])
def test_a_stranger_s_mistakes_exit_2_with_one_line(gym_id, subgoal, fragment, tmp_path, capsys):
    _refused(tmp_path, capsys, f"family: minigrid\noptions: {{gym_id: {gym_id}}}", subgoal, fragment)


@pytest.mark.parametrize("options, subgoal, fragment", [
    ("{gym_id: MiniGrid-PutNear-6x6-N2-v0}", "{name: p, kind: placed_near, args: {near: {}}}",
     "options.actions: 'drop' is missing and subgoals[0] (p) is a placed_near sub-goal; add drop to options.actions"),
    ("{gym_id: MiniGrid-DoorKey-5x5-v0, actions: [left, right, forward, pickup]}",
     "{name: door, kind: door_open, args: {}}", "'toggle' is missing and subgoals[0] (door) is a door_open"),
    ("{gym_id: MiniGrid-GoToDoor-5x5-v0}", "{name: door, kind: facing, args: {type: door}}",
     "'done' is missing and MiniGrid-GoToDoor-5x5-v0 rewards the done action"),
    ("{gym_id: MiniGrid-Empty-5x5-v0, actions: [left, right]}", "{name: spot, kind: at, args: {cell: [2, 2]}}",
     "'forward' is missing and the agent could not move"),
    ("{gym_id: MiniGrid-Unlock-v0, actions: [left, right, forward, pickup]}", "{name: key, kind: carrying, args: {}}",
     "'toggle' is missing and MiniGrid-Unlock-v0 rewards the toggle action"),
    # no sub-goal needs the missing action, but every layout's goal square lies behind a door
    ("{gym_id: MiniGrid-DoorKey-5x5-v0, actions: [left, right, forward, pickup]}", "{name: key, kind: carrying, args: {}}",
     "with ['left', 'right', 'forward', 'pickup'] the agent can reach the goal square in none of 8 seeded layouts of "
     "MiniGrid-DoorKey-5x5-v0; add toggle to options.actions"),
    ("{gym_id: MiniGrid-DoorKey-5x5-v0, actions: [left, right, forward, toggle]}", "{name: d, kind: door_open, args: {}}",
     "add pickup to options.actions"),
    ("{gym_id: MiniGrid-MultiRoom-N2-S4-v0, actions: [left, right, forward]}", "{name: g, kind: goal}",
     "add toggle to options.actions"),
])
def test_an_action_set_that_cannot_reach_a_sub_goal_or_success_is_refused(options, subgoal, fragment, tmp_path,
                                                                          capsys):
    _refused(tmp_path, capsys, f"family: minigrid\noptions: {options}", subgoal, fragment)


def test_the_done_action_where_the_environment_rewards_it_is_accepted_and_taken(tmp_path):
    path = tmp_path / "mine.yaml"
    path.write_text("task: mine\nfamily: minigrid\noptions: {gym_id: MiniGrid-GoToDoor-5x5-v0, actions: [left, right, "
                    "forward, done]}\nsubgoals:\n  - {name: door, kind: facing, args: {type: door}}\n"
                    "  - {name: goal, kind: goal}\n")
    env = make(str(path))
    assert env.unwrapped.action_names == ["left", "right", "forward", "done"] and env.action_space.n == 4


@pytest.mark.parametrize("gym_id, subgoal, fragment", [
    ("MiniGrid-DoorKey-5x5-v0", "{name: key, kind: carrying, args: {type: key, color: red}}",
     "needs a red key, and MiniGrid-DoorKey-5x5-v0 has none in 8 seeded layouts (it has: green goal, yellow door, "
     "yellow key); it holds only in layouts that have one"),
    ("MiniGrid-RedBlueDoors-6x6-v0", "{name: door, kind: door_open, args: {locked: true}}", "needs a locked door"),
])
def test_a_colour_or_lock_the_probed_layouts_lack_is_a_warning_once_as_random_layouts_may_have_it(
        gym_id, subgoal, fragment, tmp_path, capsys):
    path = tmp_path / "mine.yaml"
    path.write_text(f"task: mine\nfamily: minigrid\noptions: {{gym_id: {gym_id}}}\nsubgoals:\n  - {subgoal}\n"
                    "  - {name: goal, kind: goal}\n")
    make(str(path))
    make(str(path))
    err = capsys.readouterr().err
    assert err.count(fragment) == 1 and err.startswith("hubsgo: warning: "), err


@pytest.mark.parametrize("head, fragment", [
    ("family: gym\noptions: {gym_id: MiniGrid-DoorKey-5x5-v0}", "carrying is a kind of family minigrid"),
    ("family: minigrid\noptions: {env_id: MiniGrid-DoorKey-5x5-v0}", "name the environment, by gym_id"),
])
def test_a_stranger_s_misnamed_family_or_id_key_is_told_the_right_one(head, fragment, tmp_path, capsys):
    _refused(tmp_path, capsys, head, "{name: key, kind: carrying, args: {type: key}}", fragment)


def _refused(tmp_path, capsys, head: str, subgoal: str, fragment: str) -> None:
    path = tmp_path / "mine.yaml"
    path.write_text(f"task: mine\n{head}\nsubgoals:\n  - {subgoal}\n  - {{name: goal, kind: goal}}\n")
    assert main(["check-env", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err


def test_a_river_of_lava_parts_rooms_and_its_opening_is_a_gap():
    from minigrid.core.world_object import Goal, Lava

    g = Grid(7, 6)
    g.wall_rect(0, 0, 7, 6)
    for y in (1, 2, 4):                                         # lava at x=3, an opening at (3, 3)
        g.set(3, y, Lava())
    g.set(5, 2, Goal())
    room_of_goal = kind("in_room", type="goal")
    s = new_scene(g, (1, 1))
    assert not room_of_goal.holds(s)
    s.agent = (3, 3)                                            # in the opening: in no room
    assert not room_of_goal.holds(s)
    s.agent = (4, 4)
    assert room_of_goal.holds(s)


def test_an_environment_that_cannot_generate_a_layout_is_refused_in_one_line(tmp_path, capsys):
    import gymnasium as gym
    from minigrid.core.mission import MissionSpace
    from minigrid.minigrid_env import MiniGridEnv

    class Broken(MiniGridEnv):
        def __init__(self, **kwargs):
            super().__init__(mission_space=MissionSpace(mission_func=lambda: "get to the goal"), grid_size=5,
                             max_steps=10, **kwargs)

        def _gen_grid(self, width, height):
            raise ModuleNotFoundError("No module named 'imageio'\nsecond line")

    gym.register("HubsgoTest-Broken-v0", entry_point=Broken)
    try:
        _refused(tmp_path, capsys, "family: minigrid\noptions: {gym_id: HubsgoTest-Broken-v0}",
                 "{name: key, kind: carrying, args: {type: key}}",
                 "could not generate a layout (ModuleNotFoundError: No module named 'imageio' second line)")
    finally:
        del gym.registry["HubsgoTest-Broken-v0"]


def test_carrying_anything_aims_at_what_can_be_picked_up_not_at_a_door():
    from minigrid.core.world_object import Goal

    g = room((Door("green"), (4, 2)), (Goal(), (3, 3)), (Ball("red"), (1, 1)))
    held = kind("carrying")
    s = new_scene(g, (3, 2))
    assert held.target(s) == (1, 1)                             # the door and the goal square are nearer
    assert not kind("placed_near", near={}).holds(s)            # the ball is next to nothing


def test_the_rewarded_actions_are_read_from_the_branch_of_step_that_pays():
    from minigrid.envs import DoorKeyEnv, GoToDoorEnv, PutNearEnv, UnlockEnv, UnlockPickupEnv

    from hubsgo_ppl.envs.minigrid.registered import rewarded_actions

    # GoToDoor's step also tests toggle, which ends the episode without reward: not required
    assert rewarded_actions(GoToDoorEnv) == ["done"]
    assert rewarded_actions(UnlockEnv) == ["toggle"]
    assert rewarded_actions(UnlockPickupEnv) == ["pickup"]
    assert rewarded_actions(PutNearEnv) == ["drop"]
    assert rewarded_actions(DoorKeyEnv) == []          # MiniGrid's own step: the goal square pays


def test_the_goal_square_is_reached_only_through_a_door_the_actions_can_open():
    """room(): the agent at (1, 1), the goal at (5, 2) beyond the door at (4, 2)."""
    acts = ["left", "right", "forward"]

    def reach(door, *objects, actions, carrying=None, goal=(5, 2)):
        g = room((door, (4, 2)), (Goal(), goal), *objects)
        return goal_reachable(SimpleNamespace(grid=g, agent_pos=(1, 1), carrying=carrying), actions)

    assert reach(Door("red", is_open=True), actions=acts) is True
    assert reach(Door("red"), actions=acts) is False
    assert reach(Door("red"), actions=[*acts, "toggle"]) is True
    locked = Door("red", is_locked=True)
    assert reach(locked, actions=[*acts, "toggle"]) is False
    assert reach(locked, (Key("red"), (2, 3)), actions=[*acts, "toggle"]) is False
    assert reach(locked, (Key("red"), (2, 3)), actions=[*acts, "pickup", "toggle"]) is True
    assert reach(locked, (Key("blue"), (2, 3)), actions=[*acts, "pickup", "toggle"]) is False
    assert reach(locked, (Box("green", contains=Key("red")), (2, 3)), actions=[*acts, "pickup"]) is False
    assert reach(locked, (Box("green", contains=Key("red")), (2, 3)), actions=[*acts, "pickup", "toggle"]) is True
    assert reach(locked, actions=[*acts, "toggle"], carrying=Key("red")) is True
    # a key beyond its own door, and a wall of lava before the door, are never passed
    assert reach(locked, (Key("red"), (6, 3)), actions=[*acts, "pickup", "toggle"]) is False
    lava = [(Lava(), (3, y)) for y in range(1, 4)]
    assert reach(Door("red", is_open=True), *lava, actions=acts) is False
    # a ball in the doorway's way is taken away only with pickup
    assert reach(Door("red", is_open=True), (Ball("red"), (3, 2)), (Ball("red"), (3, 1)), (Ball("red"), (3, 3)),
                 actions=acts) is False
    assert reach(Door("red", is_open=True), (Ball("red"), (3, 2)), (Ball("red"), (3, 1)), (Ball("red"), (3, 3)),
                 actions=[*acts, "pickup"]) is True
    assert goal_reachable(SimpleNamespace(grid=room(), agent_pos=(1, 1), carrying=None), acts) is None
    env = SimpleNamespace(grid=room((locked, (4, 2)), (Goal(), (5, 2)), (Key("red"), (2, 3))), agent_pos=(1, 1),
                          carrying=None)
    assert missing_for_goal(env, acts) == ["toggle", "pickup"] and missing_for_goal(env, [*acts, "pickup"]) == ["toggle"]
