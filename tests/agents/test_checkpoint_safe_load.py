"""Every agent's checkpoint loads through the safe (weights-only) loader that ``hubsgo evaluate``,
``--resume``, ``review`` and ``revise`` use, in the states a run can stop in: freshly built, after a few
steps, and (the learned arm low level) right after an episode ended, when its pending trajectory is
empty. Each state is saved as ``hubsgo train`` saves it, read back with ``load_checkpoint`` and loaded
into a fresh agent, whose state must then be the same.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hubsgo_ppl.experiments.io import load_checkpoint, save_torch
from hubsgo_ppl.experiments.restore import build_run
from hubsgo_ppl.experiments.resolve import resolve_run
from hubsgo_ppl.experiments.resolved import RunConfig


def _same(a, b) -> bool:
    """Whether two states hold the same values (tensors, numpy arrays and plain data alike)."""
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, (torch.Tensor, np.ndarray)) or isinstance(b, (torch.Tensor, np.ndarray)):
        x, y = np.asarray(a), np.asarray(b)
        return x.shape == y.shape and np.array_equal(x, y, equal_nan=True)
    return a == b


def _round_trip(tmp_path, run, agent) -> None:
    state = agent.state_dict()
    save_torch(tmp_path / "checkpoint.pt", {"format": 1, "agent": state})
    loaded = load_checkpoint(tmp_path / "checkpoint.pt")["agent"]       # refuses pickled code or objects
    env2, fresh = build_run(run)
    try:
        fresh.load_state_dict(loaded)
        assert _same(fresh.state_dict(), state)
    finally:
        env2.close()


def _play(agent, steps: int) -> None:
    """Train ``agent`` for at least ``steps`` env steps (whole episodes, as ``hubsgo train`` does)."""
    done = 0
    while done < steps:
        done += sum(e.length for e in agent.train_chunk())


MAZE_AGENTS = [("hubsgo", "learned"), ("hubsgo", "scripted"), ("hdqn", "learned"), ("ddqn", None), ("ppo", None)]
# small replay buffers and rollouts: the states are the same kinds of data, a few MB rather than hundreds
SMALL = {"hubsgo": ["low.buffer_size=500", "high.buffer_size=500"], "hdqn": ["low.buffer_size=500", "high.buffer_size=500"],
         "ddqn": ["dqn.buffer_size=500", "dqn.learning_starts=20"], "ppo": ["ppo.n_steps=32", "ppo.batch_size=16"]}


@pytest.mark.parametrize("agent_name,low", MAZE_AGENTS)
def test_a_maze_agent_checkpoint_loads_safely(agent_name, low, tmp_path):
    overrides = ["env.max_steps=40", *(SMALL[agent_name] if low != "scripted" else ["high.buffer_size=500"])]
    run = resolve_run(RunConfig(task="keydoor", agent=agent_name, steps=2000, seed=0, low_level=low,
                                overrides=overrides))
    env, agent = build_run(run)
    try:
        _round_trip(tmp_path, run, agent)
        _play(agent, 60)
        _round_trip(tmp_path, run, agent)
    finally:
        env.close()


@pytest.mark.mujoco
@pytest.mark.parametrize("agent_name,low", [("hubsgo", "learned"), ("hubsgo", "scripted"), ("hiro", None),
                                            ("td3", None)])
def test_an_arm_agent_checkpoint_loads_safely(agent_name, low, tmp_path):
    pytest.importorskip("robosuite")
    run = resolve_run(RunConfig(task="push_any_one", agent=agent_name, steps=2000, seed=0, low_level=low,
                                overrides=["env.horizon=40"] + (["loop.option_steps=10"] if low else [])))
    env, agent = build_run(run)
    try:
        _round_trip(tmp_path, run, agent)
        _play(agent, 40)
        _round_trip(tmp_path, run, agent)
    finally:
        env.close()


@pytest.mark.mujoco
def test_the_learned_arm_low_level_loads_safely_between_trajectories(tmp_path):
    """The state a run stops in after a successful episode: no pending transitions (an empty
    trajectory), which a numpy array would store as a ``bytes()`` call that the safe loader refuses."""
    pytest.importorskip("robosuite")
    run = resolve_run(RunConfig(task="push_any_one", steps=2000, seed=0, low_level="learned",
                                overrides=["env.horizon=30", "loop.option_steps=10"]))
    env, agent = build_run(run)
    try:
        _play(agent, 30)
        agent.low.end_trajectory()
        assert all(len(v) == 0 for v in agent.low._traj.values()) and agent.low._goal is not None
        _round_trip(tmp_path, run, agent)
    finally:
        env.close()
