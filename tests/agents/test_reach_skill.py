"""The shipped reach skill of the learned arm low level (hubsgo_ppl/agents/reach_skill.pt): a small file of
tensors that loads with ``weights_only=True``, and a policy that reaches held-out targets on an arm task."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import torch


def test_the_skill_file_is_small_and_holds_only_tensors_and_plain_data():
    path = resources.files("hubsgo_ppl.agents") / "reach_skill.pt"
    with resources.as_file(path) as file:
        assert file.stat().st_size <= 2 * 1024 * 1024
        state = torch.load(file, map_location="cpu", weights_only=True)
    assert set(state) == {"actor", "critics", "hidden", "meta"} and state["hidden"] == [128, 128]
    assert state["actor"]["0.weight"].shape == (128, 4) and state["actor"]["4.weight"].shape == (3, 128)


@pytest.mark.mujoco
def test_the_skill_reaches_held_out_targets_and_does_not_fit_other_networks():
    pytest.importorskip("robosuite")
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from reach_skill import RandomTargets, episode

    from hubsgo_ppl.agents.td3_her import GoalTD3
    from hubsgo_ppl.envs.robosuite import make_robosuite_task
    from hubsgo_ppl.resources import envs_dir

    torch.set_num_threads(1)
    env = make_robosuite_task(str(envs_dir() / "push_any_one.yaml"), horizon=10**6)
    try:
        agent = GoalTD3.for_env(env, {}, torch.Generator().manual_seed(0), np.random.default_rng(0))
        targets = RandomTargets(env, np.random.default_rng(12345), 0.15, (0.03, 0.3))   # not the training draws
        reached = [episode(env, targets, agent, 500 + i, 40, 0.0, train=False) for i in range(20)]
        assert np.mean(reached) >= 0.95, reached
        with pytest.raises(ValueError, match=r"low.skill=reach: .* set low.skill=null"):
            GoalTD3.for_env(env, {"hidden": [32]}, torch.Generator().manual_seed(0), np.random.default_rng(0))
        scratch = GoalTD3.for_env(env, {"skill": None}, torch.Generator().manual_seed(0), np.random.default_rng(0))
        assert not torch.equal(scratch.actor.state_dict()["0.weight"], agent.actor.state_dict()["0.weight"])
    finally:
        env.close()
