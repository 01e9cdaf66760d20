"""Stacked GoalDQN low levels (several seeds' networks updated together) against each seed's own."""

import copy

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.low_level import GoalDQN
from hubsgo_ppl.agents.settings import GoalDQNConfig
from hubsgo_ppl.agents.stacked import StackedGoalDQN

D, N, A = 12, 3, 4


def _low(seed, **cfg):
    config = GoalDQNConfig(hidden=(16, 16), batch_size=8, learning_starts=8, grad_clip=0.5, **cfg)
    low = GoalDQN(D, N, A, config, torch.Generator().manual_seed(seed), np.random.default_rng(seed),
                  potential=(lambda obs: -obs[..., :N]) if cfg.get("shaping") else None)
    r = np.random.default_rng(50 + seed)
    for _ in range(40):
        low.store(r.random(D).astype(np.float32), int(r.integers(A)), r.random(D).astype(np.float32),
                  r.random(N) < 0.3, r.random(N) < 0.5, bool(r.random() < 0.1))
    return low


def _same(a: GoalDQN, b: GoalDQN):
    sa, sb = a.state_dict(), b.state_dict()
    for key in ("q", "q_target"):
        for k in sa[key]:
            assert torch.equal(sa[key][k], sb[key][k]), (key, k)
    for i, st in sa["opt"]["state"].items():
        for k in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(st[k], sb["opt"]["state"][i][k]), (i, k)
    assert a.buffer.rng.bit_generator.state == b.buffer.rng.bit_generator.state


@pytest.mark.parametrize("shaping", [0.0, 1.0])
def test_stacked_steps_equal_each_seeds_own_steps(shaping):
    lows = [_low(s, shaping=shaping) for s in range(3)]
    alone = copy.deepcopy(lows)
    lows[2].goal_weight = alone[2].goal_weight = torch.tensor([1.0, 0.5, 0.25])
    stacked = StackedGoalDQN(lows)
    for _ in range(3):
        got = stacked.update([0, 1, 2])
        want = [low.update() for low in alone]
        assert got == want
    # a subset: seed 1 alone steps; seeds 0 and 2 are left as they were
    frozen = copy.deepcopy(lows[0].state_dict())
    assert stacked.update([1]) == [alone[1].update()]
    for k in range(3):
        _same(lows[k], alone[k])
    assert all(torch.equal(v, lows[0].state_dict()["q"][k]) for k, v in frozen["q"].items())
    # the seeds' modules are views of the stack: their own greedy actions agree with the batched ones
    obs = {k: np.random.default_rng(k).random(D).astype(np.float32) for k in range(3)}
    batched = stacked.greedy({k: (obs[k], k % N) for k in range(3)})
    assert batched == {k: alone[k].greedy(obs[k], k % N) for k in range(3)}
    assert batched == {k: lows[k].greedy(obs[k], k % N) for k in range(3)}


def test_a_stacked_seeds_checkpoint_holds_only_its_own_tensors_and_loads_into_a_run_alone(tmp_path):
    lows = [_low(s) for s in range(2)]
    stacked = StackedGoalDQN(lows)
    stacked.update([0, 1])
    path = tmp_path / "low.pt"
    torch.save(lows[1].state_dict(), path)
    alone = _low(1)
    alone.load_state_dict(torch.load(path, weights_only=False))
    alone.rng.bit_generator.state = lows[1].rng.bit_generator.state     # the loop checkpoints the stream
    assert all(torch.equal(a, b) for a, b in zip(alone.q.parameters(), lows[1].q.parameters()))
    q = lows[1].state_dict()["q"]
    assert all(v.untyped_storage().nbytes() == v.numel() * 4 for v in q.values())   # not the stack's storage
    assert alone.update() == stacked.update([1])[0]


def test_unlike_low_levels_are_refused():
    with pytest.raises(ValueError, match="cannot be stacked"):
        StackedGoalDQN([_low(0), _low(1, gamma=0.9)])
