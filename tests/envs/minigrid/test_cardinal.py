"""The cardinal action set (``actions: [east, south, west, north]``): moves, pickup and opening on
contact, on hand-built states of the shipped KeyDoorCardinal; the planner agrees with the env."""

import numpy as np
import pytest

from hubsgo_ppl.envs import make, register
from hubsgo_ppl.envs.minigrid.bfs import optimal_steps, plan, transition
from hubsgo_ppl.envs.minigrid.cardinal import primitive
from hubsgo_ppl.specs import SpecError

E, S, W, N = 0, 1, 2, 3     # the catalogue's order: [east, south, west, north]


@pytest.fixture
def env():
    register()
    e = make("keydoor_cardinal")
    e.reset(seed=0)
    yield e.unwrapped
    e.close()


def _put(env, cell):
    env.agent_pos = np.array(cell)


def test_moving_into_a_key_picks_it_up_and_the_agent_stays(env):
    _put(env, (4, 4))                       # the yellow key lies at (4, 3), north of the agent
    env.step(N)
    assert env.carrying is not None and (env.carrying.type, env.carrying.color) == ("key", "yellow")
    assert tuple(env.agent_pos) == (4, 4) and env.agent_dir == 3 and env.grid.get(4, 3) is None
    env.step(N)                             # the cell is free now: the agent steps onto it
    assert tuple(env.agent_pos) == (4, 3)


def test_a_locked_door_opens_only_with_the_key_of_its_colour(env):
    _put(env, (7, 4))                       # the locked yellow door is at (8, 4), east
    _, _, _, _, info = env.step(E)
    door = env.grid.get(8, 4)
    assert door.is_locked and not door.is_open and tuple(env.agent_pos) == (7, 4)
    env.carrying = env.grid.get(4, 9)       # the blue key: the wrong colour
    env.step(E)
    assert door.is_locked and not door.is_open
    env.carrying = env.grid.get(4, 3)       # the yellow key
    _, _, _, _, info = env.step(E)
    assert door.is_open and tuple(env.agent_pos) == (7, 4)
    assert info["subgoals"][env.subgoal_names.index("yellow_door")]
    env.step(E)
    assert tuple(env.agent_pos) == (8, 4)   # through the open door


def test_into_a_wall_the_agent_stays_and_the_step_counts(env):
    _put(env, (1, 6))
    before = env.step_count
    env.step(W)                             # (0, 6) is the border wall
    assert tuple(env.agent_pos) == (1, 6) and env.agent_dir == 2 and env.step_count == before + 1
    env.step(S)
    assert tuple(env.agent_pos) == (1, 7) and env.agent_dir == 1


def test_carrying_a_key_the_other_blocks_the_way(env):
    _put(env, (4, 8))
    env.carrying = env.grid.get(4, 3)
    env.grid.set(4, 3, None)
    env.step(S)                             # the blue key at (4, 9): hands full, it stays on the floor
    assert tuple(env.agent_pos) == (4, 8) and env.grid.get(4, 9).color == "blue"
    assert env.carrying.color == "yellow"


def test_reaching_the_goal_pays_minigrid_reward():
    register()
    e = make("keydoor_cardinal")
    e.reset(seed=0)
    actions = plan(e.unwrapped)
    assert len(actions) == optimal_steps("keydoor_cardinal") == 16
    for a in actions:
        _, r, term, trunc, info = e.step(a)
    assert term and info["is_success"] and r == pytest.approx(1 - 0.9 * 16 / 2000)


def test_planner_transition_matches_the_env_on_a_random_walk():
    register()
    e = make("keydoor_cardinal")
    e.reset(seed=0)
    task = e.unwrapped
    rng = np.random.default_rng(0)
    for _ in range(400):
        a = int(rng.integers(4))
        expected = transition(task.spec_maze, task.symbolic_state(), ["east", "south", "west", "north"][a])
        _, _, term, _, _ = e.step(a)
        assert task.symbolic_state() == expected
        if term:
            e.reset(seed=1)


def test_primitive_table():
    assert primitive("object", carrying=False) == "pickup"
    assert primitive("object", carrying=True) == "forward"
    assert primitive("door", carrying=False) == "toggle"
    assert primitive("other", carrying=True) == "forward"


def test_cardinal_moves_cannot_be_mixed_with_minigrid_actions(tmp_path):
    from hubsgo_ppl.envs.minigrid.layout import load_maze_spec
    from hubsgo_ppl.resources import envs_dir

    text = (envs_dir() / "keydoor_cardinal.yaml").read_text()
    (tmp_path / "keydoor.txt").write_text((envs_dir() / "keydoor.txt").read_text())
    bad = tmp_path / "mixed.yaml"
    bad.write_text(text.replace("actions: [east, south, west, north]", "actions: [east, forward]"))
    with pytest.raises(SpecError, match="cardinal moves .* cannot be mixed"):
        load_maze_spec(bad)
    bad.write_text(text.replace("actions: [east, south, west, north]", "actions: [east, up]"))
    with pytest.raises(SpecError, match=r"unknown action\(s\) \['up'\].*cardinal moves east, south, west, north"):
        load_maze_spec(bad)
