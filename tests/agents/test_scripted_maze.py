"""The scripted maze low level: one option reaches a reachable sub-goal in the fewest moves (checked
against the full-task BFS on KeyDoor), an unreachable one costs turns only, and `--low-level scripted`
trains a maze."""

from __future__ import annotations

import numpy as np
import pytest

from hubsgo_ppl.agents.config import resolve_hyper
from hubsgo_ppl.agents.factory import build_agent
from hubsgo_ppl.agents.low_level import ScriptedLowLevel
from hubsgo_ppl.agents.scripted_maze import ScriptedMaze
from hubsgo_ppl.envs import make
from hubsgo_ppl.envs.minigrid import bfs


def _run_option(env, controller, goal, limit=200):
    """Act towards ``goal`` until it holds or ``limit`` steps; (steps, achieved, actions)."""
    idx = env.unwrapped.subgoal_names.index(goal)
    controller.reset()
    names = list(env.unwrapped.spec_maze.options.actions)
    taken = []
    for step in range(1, limit + 1):
        a = controller.act(env, idx)
        taken.append(names[a])
        _, _, terminated, truncated, info = env.step(a)
        if info["subgoals"][idx]:
            return step, True, taken
        if terminated or truncated:
            break
    return step, False, taken


def test_three_options_replay_the_optimal_keydoor_episode():
    # key, door, goal as three options: together they take exactly the BFS optimum (19 steps)
    env = make("keydoor")
    env.reset(seed=0)
    total = 0
    for goal in ("yellow_key", "yellow_door", "goal"):
        steps, ok, _ = _run_option(env, ScriptedMaze(), goal)
        assert ok
        total += steps
    blue = make("keydoor")
    blue.reset(seed=0)
    total_blue = sum(_run_option(blue, ScriptedMaze(), g)[0] for g in ("blue_key", "blue_door", "goal"))
    assert min(total, total_blue) == bfs.optimal_steps("keydoor")


def test_only_the_last_action_interacts_and_blocked_targets_cost_turns_only():
    env = make("keydoor")
    env.reset(seed=0)
    # the goal lies behind a locked door: no option reaches it, and the planner only turns in place
    start = env.unwrapped.symbolic_state()
    steps, ok, taken = _run_option(env, ScriptedMaze(), "goal", limit=12)
    assert not ok and set(taken) <= {"left"}
    assert env.unwrapped.symbolic_state()._replace(dir=start.dir) == start
    # reaching a door picks up no key on the way: the door is unreachable without its key
    steps, ok, taken = _run_option(env, ScriptedMaze(), "blue_door", limit=12)
    assert not ok and "pickup" not in taken
    # a key: moves, then one pickup as the last action
    steps, ok, taken = _run_option(env, ScriptedMaze(), "blue_key")
    assert ok and taken[-1] == "pickup" and set(taken[:-1]) <= {"left", "right", "forward"}


def test_plan_or_none_bounds_the_search():
    env = make("keydoor")
    env.reset(seed=0)
    goal = env.unwrapped.subgoal_names.index("goal")
    assert bfs.plan_or_none(env, goal) is None
    key = env.unwrapped.subgoal_names.index("yellow_key")
    assert bfs.plan_or_none(env, key, max_states=3) is None          # gave up
    path = bfs.plan_or_none(env, key)
    assert path and len(path) < len(bfs.plan(env))
    with pytest.raises(ValueError, match=r"low.max_states takes an integer >= 1 \(default 200000\), got 0$"):
        resolve_hyper("minigrid", "keydoor", "hubsgo", ["low.max_states=0"], low_level="scripted")
    with pytest.raises(TypeError, match="not a maze task"):
        ScriptedMaze().act(_NotAMaze(), 0)


class _NotAMaze:
    unwrapped = object()


def test_low_level_scripted_trains_a_maze_with_its_own_settings_only():
    hyper = resolve_hyper("minigrid", "keydoor", "hdqn", [], steps=600, low_level="scripted")
    assert hyper["low"] == {}                       # the learned low level's preset does not apply
    env = make("keydoor")
    agent = build_agent("hdqn", env, hyper, seed=0)
    assert isinstance(agent.low, ScriptedLowLevel) and isinstance(agent.low.controller, ScriptedMaze)
    stats = []
    while agent.env_steps < 600:
        stats += agent.train_chunk()
    assert any(s.success for s in stats)            # a random high level over perfect options succeeds
    assert max(s.options for s in stats) >= 3
    assert np.mean([s.success for s in stats]) > 0.5
