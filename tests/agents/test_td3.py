"""TD3Core (the TD3 core shared by HIRO and GoalTD3): SB3's Polyak update, the multi-tensor Adam and Polyak
steps against the per-tensor ones, the initialisation order, checkpoint names, and target clipping."""

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


def test_multi_tensor_adam_and_polyak_give_the_per_tensor_loops_floats_and_a_per_tensor_state_resumes(monkeypatch):
    from hubsgo_ppl.agents import td3

    ours, theirs = _core(), _core()
    for opt in (theirs.actor_opt, theirs.critic_opt):       # torch's default on CPU: one tensor at a time
        for group in opt.param_groups:
            group["foreach"] = None
    g = torch.Generator().manual_seed(2)

    def step(core, per_tensor):
        batch = [torch.randn(32, 5, generator=g), torch.rand(32, 2, generator=g) * 2 - 1,
                 torch.randn(32, generator=g), torch.randn(32, 5, generator=g), 0.9, torch.randn(32, 2, generator=g)]
        with monkeypatch.context() as m:
            if per_tensor:
                m.setattr(td3, "_polyak", lambda a, b, tau: polyak_update(a.parameters(), b.parameters(), tau))
            core.update(*batch)

    def same(a, b):
        sa, sb = a.state_dict(), b.state_dict()
        return all(torch.equal(x, y) for k in ("actor", "actor_target", "critics", "critics_target")
                   for x, y in zip(sa[k].values(), sb[k].values())) and all(
            torch.equal(x["exp_avg_sq"], y["exp_avg_sq"]) for k in ("actor_opt", "critic_opt")
            for x, y in zip(sa[k]["state"].values(), sb[k]["state"].values()))

    for _ in range(7):
        state = g.get_state()
        step(ours, False)
        g.set_state(state)
        step(theirs, True)
    assert same(ours, theirs) and ours.actor_opt.state_dict()["state"]      # the actor has stepped too
    again = _core()
    again.load_state_dict(theirs.state_dict())      # a state written by the per-tensor loop
    again.updates = theirs.updates                  # the caller's to store
    assert all(grp["foreach"] for opt in (again.actor_opt, again.critic_opt) for grp in opt.param_groups)
    for core in (ours, again):
        g.manual_seed(3)
        for _ in range(4):
            step(core, False)
    assert same(ours, again)


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
