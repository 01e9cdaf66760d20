"""TD3Core (the TD3 core shared by HIRO and GoalTD3): SB3's Polyak update, the initialisation order, checkpoint
names, and target clipping."""

import numpy as np
import torch
from stable_baselines3.common.utils import polyak_update

from hubsgo_ppl.agents.nets import mlp
from hubsgo_ppl.agents.td3 import TD3Core


def _core(order=("actor", "critics", "actor_target", "critics_target"), **kw):
    args = dict(actor_lr=1e-3, critic_lr=1e-3, tau=0.05, policy_delay=2, target_noise=0.2, target_noise_clip=0.5)
    return TD3Core(5, 2, (16,), torch.Generator().manual_seed(0), init_order=order, **{**args, **kw})


def test_polyak_update_is_the_in_place_formula_bit_for_bit():
    g = torch.Generator().manual_seed(1)
    net, a, b = (mlp(4, (8,), 3, g) for _ in range(3))
    b.load_state_dict(a.state_dict())
    with torch.no_grad():
        for p, pt in zip(net.parameters(), a.parameters()):
            pt.mul_(1 - 0.005).add_(p, alpha=0.005)
    polyak_update(net.parameters(), b.parameters(), 0.005)
    assert all(torch.equal(x, y) for x, y in zip(a.parameters(), b.parameters()))


def test_init_order_decides_which_network_gets_which_draws():
    a = _core()
    b = _core(("actor", "actor_target", "critics", "critics_target"))
    assert torch.equal(a.actor[0].weight, b.actor[0].weight)          # first either way
    assert not torch.equal(a.critics[0][0].weight, b.critics[0][0].weight)
    for core in (a, b):                                               # targets start as copies
        assert torch.equal(core.actor[0].weight, core.actor_target[0].weight)
        assert torch.equal(core.critics[1][0].weight, core.critics_target[1][0].weight)


def test_update_state_names_and_target_range():
    core = _core(scale=np.array([2.0, 0.5], np.float32), target_range=(-1.0, 0.0))
    x, a = torch.randn(8, 5), torch.rand(8, 2) - 0.5
    steps = [core.update(x, a, -torch.ones(8), torch.randn(8, 5), 0.9, torch.randn(8, 2)) for _ in range(2)]
    assert steps[0].actor_loss is None and steps[1].actor_loss is not None and core.updates == 2
    assert (core.mu(x).abs() <= torch.tensor([2.0, 0.5])).all()
    names = {"actor": "pi", "critics": "q", "actor_target": "pi_t", "critics_target": "q_t", "actor_opt": "o1",
             "critic_opt": "o2"}
    state = core.state_dict(names)
    assert list(state) == list(names.values())
    other = _core(scale=np.array([2.0, 0.5], np.float32))
    other.load_state_dict(state, names)
    assert torch.equal(other.mu(x), core.mu(x))
    assert list(core.state_dict()) == list(TD3Core.STATE)
