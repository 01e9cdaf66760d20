"""Scripted OSC low level: its command law, and that each task's correct sub-goal sequence solves it.

The solve tests double as the smoke run of the arm tasks until the HRL loop drives them.
"""

from __future__ import annotations

import numpy as np
import pytest

from hubsgo_ppl.agents.scripted_osc import ScriptedOSC

pytest.importorskip("robosuite", reason="robosuite is not installed: the arm-task tests are skipped (install "
                    "the 'robosuite' extra; 'make test' sets HUBSGO_REQUIRE_ROBOSUITE=1 and fails instead)")

from hubsgo_ppl.envs.robosuite import make_robosuite_task  # noqa: E402
from hubsgo_ppl.resources import envs_dir  # noqa: E402

mujoco = pytest.mark.mujoco
_envs: dict = {}


def task_env(task: str):
    if task not in _envs:
        _envs[task] = make_robosuite_task(str(envs_dir() / f"{task}.yaml"))
    return _envs[task]


def run_sequence(env, names: list[str], seed: int, per_goal: int):
    """Execute sub-goals in order, each until achieved (or ``per_goal`` steps); return info, steps, path."""
    ctl = ScriptedOSC()
    _, info = env.reset(seed=seed)
    steps, path, prev = 0, 0.0, env.unwrapped.eef_position()
    terminated = False
    for name in names:
        i = env.unwrapped.subgoal_names.index(name)
        for _ in range(per_goal):
            if info["subgoals"][i] or terminated:
                break
            _, reward, terminated, truncated, info = env.step(ctl.act(env, i))
            steps += 1
            now = env.unwrapped.eef_position()
            path, prev = path + float(np.linalg.norm(now - prev)), now
            assert reward == float(terminated)      # sparse: 1 exactly on the success step
            assert not truncated
    return info, steps, path


def test_rejects_bad_settings():
    from hubsgo_ppl.agents.config import ConfigError, resolve_hyper

    with pytest.raises(ConfigError, match=r"^--set low.gain=0: low.gain takes a finite number > 0 \(default 20.0\), got 0$"):
        resolve_hyper("robosuite", "push_any_one", "hubsgo", ["low.gain=0"])
    with pytest.raises(ConfigError, match=r"low.tolerance takes a finite number >= 0 \(default 0.002\), got '-1e-3'$"):
        resolve_hyper("robosuite", "push_any_one", "hubsgo", ["low.tolerance=-1e-3"])


def test_rejects_an_env_without_the_subgoal_interface():
    import gymnasium as gym
    env = gym.make("CartPole-v1")
    with pytest.raises(TypeError, match="not a robosuite sub-goal task"):
        ScriptedOSC().act(env, 0)


@mujoco
def test_command_law():
    env = task_env("stack_cubes")
    env.reset(seed=0)
    ctl = ScriptedOSC(gain=20.0, tolerance=0.002)
    i = env.unwrapped.subgoal_names.index("grasp_red")
    xyz, g = env.unwrapped.subgoal_target(i)
    a = ctl.act(env, i)
    expected = np.clip(20.0 * (xyz - env.unwrapped.eef_position()), -1, 1)
    assert a.dtype == np.float32 and a.shape == (4,)
    np.testing.assert_allclose(a[:3], expected, atol=1e-6)
    assert a[3] == g == -1.0
    # inside the tolerance the hand holds still
    assert np.all(ScriptedOSC(tolerance=10.0).act(env, i)[:3] == 0.0)


@mujoco
@pytest.mark.parametrize("seed", [0, 1])
def test_solves_stack_cubes(seed):
    env = task_env("stack_cubes")
    info, steps, _ = run_sequence(env, ["grasp_red", "place_red_on_target", "grasp_green", "place_green_on_red"],
                                  seed, per_goal=100)
    assert info["is_success"], steps
    assert steps <= 250     # measured 101-135 steps on seeds 0-2


@mujoco
@pytest.mark.parametrize("colour,seed", [("red", 0), ("green", 1), ("blue", 2)])
def test_solves_push_any_one(colour, seed):
    env = task_env("push_any_one")
    info, steps, _ = run_sequence(env, [f"push_{colour}_to_{colour}"], seed, per_goal=200)
    assert info["is_success"], steps
    assert steps <= 200     # the catalogue horizon; measured 53-146 steps


@mujoco
def test_solves_collect_three_balls_and_one_side_is_cheaper():
    env = task_env("collect_three_balls")
    one_side, steps, path_one = run_sequence(env, ["collect_ball_3", "collect_ball_4", "collect_ball_5"], 1, 200)
    assert one_side["is_success"] and steps <= 600, steps
    mixed, _, path_mixed = run_sequence(env, ["collect_ball_3", "collect_ball_0", "collect_ball_4"], 1, 200)
    assert mixed["is_success"]
    # crossing the wall twice costs end-effector travel (measured 1.78 m vs 2.99 m on seed 1)
    assert path_mixed > path_one + 0.3
