"""Seeded MLPs: layout, reproducible initialisation from the given generator only, torch's bounds."""

import math

import pytest

import torch
from torch import nn

from hubsgo_ppl.agents.nets import mlp, seeded_init_


def test_layout_and_forward_shape():
    net = mlp(5, [8, 4], 3, torch.Generator().manual_seed(0))
    assert [type(m) for m in net] == [nn.Linear, nn.ReLU, nn.Linear, nn.ReLU, nn.Linear]
    assert [(m.in_features, m.out_features) for m in net if isinstance(m, nn.Linear)] == [(5, 8), (8, 4), (4, 3)]
    assert net(torch.zeros(7, 5)).shape == (7, 3)
    assert [m.out_features for m in mlp(2, [], 6, torch.Generator()) if isinstance(m, nn.Linear)] == [6]


def test_init_comes_from_the_generator_not_the_global_rng():
    torch.manual_seed(123)
    a = mlp(6, [16], 2, torch.Generator().manual_seed(7))
    torch.manual_seed(999)                                  # a different global state changes nothing
    b = mlp(6, [16], 2, torch.Generator().manual_seed(7))
    c = mlp(6, [16], 2, torch.Generator().manual_seed(8))
    for (ka, va), (_, vb), (_, vc) in zip(a.state_dict().items(), b.state_dict().items(), c.state_dict().items()):
        assert torch.equal(va, vb), ka
        assert not torch.equal(va, vc), ka


def test_seeded_init_uses_torchs_default_bounds():
    layer = nn.Linear(25, 400)
    assert seeded_init_(layer, torch.Generator().manual_seed(0)) is layer
    bound = 1 / math.sqrt(25)
    for p in (layer.weight, layer.bias):
        assert p.abs().max() <= bound and p.abs().max() > 0.95 * bound


def _linear(generator):
    """A one-weight network w * x + b, so that a step can be computed by hand."""
    return mlp(1, [], 1, generator)


def test_target_network_starts_equal_then_follows_by_polyak_after_a_plain_adam_step():
    from hubsgo_ppl.agents.nets import TargetNetwork

    g = torch.Generator().manual_seed(0)
    net = TargetNetwork(lambda: _linear(g), lr=0.1, tau=0.25)
    w0, b0 = net.online[0].weight.item(), net.online[0].bias.item()
    assert net.target[0].weight.item() == w0 and net.target[0].bias.item() == b0
    x = torch.tensor([[2.0]])
    net.step((net.online(x) - 10.0).pow(2).sum())
    # Adam's first step moves each parameter by lr against the sign of its gradient (here: up)
    w1, b1 = net.online[0].weight.item(), net.online[0].bias.item()
    assert w1 == pytest.approx(w0 + 0.1, abs=1e-6) and b1 == pytest.approx(b0 + 0.1, abs=1e-6)
    assert net.target[0].weight.item() == pytest.approx(0.75 * w0 + 0.25 * w1, abs=1e-7)
    assert net.target[0].bias.item() == pytest.approx(0.75 * b0 + 0.25 * b1, abs=1e-7)


def test_target_network_clips_gradients_where_asked_and_round_trips_under_the_learners_names():
    from hubsgo_ppl.agents.nets import TargetNetwork

    def sgd_step(grad_clip):
        g = torch.Generator().manual_seed(1)
        net = TargetNetwork(lambda: _linear(g), lr=1.0, tau=1.0, grad_clip=grad_clip)
        net.opt = torch.optim.SGD(net.online.parameters(), lr=1.0)      # a step of exactly the gradient
        before = [p.detach().clone() for p in net.online.parameters()]
        net.step((net.online(torch.tensor([[3.0]])) - 100.0).pow(2).sum())
        return net, torch.cat([(b - p.detach()).flatten() for b, p in zip(before, net.online.parameters())])

    _, free = sgd_step(None)
    net, clipped = sgd_step(0.5)
    assert free.norm() > 10 and float(clipped.norm()) == pytest.approx(0.5, rel=1e-5)
    assert torch.allclose(clipped / clipped.norm(), free / free.norm())         # the direction kept
    state = net.state_dict(target="q_t")
    assert set(state) == {"q", "q_t", "opt"}
    other = TargetNetwork(lambda: _linear(torch.Generator().manual_seed(9)), lr=1.0, tau=1.0)
    other.load_state_dict(state, target="q_t")
    assert torch.equal(other.target[0].weight, net.target[0].weight)


def _reference_step(net, loss, tau, clip):
    """The textbook step TargetNetwork.step stands for: torch's Adam, clip_grad_norm_, SB3's polyak_update."""
    from stable_baselines3.common.utils import polyak_update

    from hubsgo_ppl.agents.nets import flushing_subnormals

    net.opt.zero_grad()
    loss.backward()
    if clip is not None:
        nn.utils.clip_grad_norm_(net.online.parameters(), clip)
    with flushing_subnormals():         # the learners' Adam flushes subnormal moments
        net.opt.step()
    polyak_update(net.online.parameters(), net.target.parameters(), tau)


@pytest.mark.parametrize("clip, hidden", [(None, [16, 16]), (0.05, [16, 16]), (0.05, [7, 13])])
def test_target_network_step_equals_torchs_adam_clipping_and_polyak_to_the_bit(clip, hidden):
    from hubsgo_ppl.agents.nets import TargetNetwork

    def make(seed):
        return TargetNetwork(lambda g=torch.Generator().manual_seed(seed): mlp(6, hidden, 3, g), 1e-2, 0.05, clip)

    fast, ref = make(3), make(3)
    x, y = torch.randn(32, 6, generator=torch.Generator().manual_seed(1)), torch.zeros(32, 3)
    for i in range(8):
        if i == 4:      # a resume: the loaded tensors replace the flat buffers' views, which are rebuilt
            state = fast.state_dict()
            fast = make(5)
            fast.load_state_dict(state)
        fast.step((fast.online(x) - y).pow(2).mean())
        _reference_step(ref, (ref.online(x) - y).pow(2).mean(), 0.05, clip)
    for a, b in ((fast.online, ref.online), (fast.target, ref.target)):
        for (k, va), vb in zip(a.state_dict().items(), b.state_dict().values()):
            assert torch.equal(va, vb), k
    sa, sb = fast.opt.state_dict()["state"], ref.opt.state_dict()["state"]
    assert sa.keys() == sb.keys() and len(sa) == 6
    for i in sa:
        for key in ("step", "exp_avg", "exp_avg_sq"):
            assert torch.equal(sa[i][key], sb[i][key]), (i, key)
    assert not torch.equal(fast.online[0].weight, make(3).online[0].weight)     # it did learn


def test_flushing_subnormals_zeroes_them_inside_the_block_only():
    from hubsgo_ppl.agents.nets import flushing_subnormals

    tiny = torch.tensor([1e-39, 3e-39, 1.0])
    assert tiny[0] > 0                                  # a subnormal float32
    with flushing_subnormals():
        assert torch.equal(tiny * 1.0, torch.tensor([0.0, 0.0, 1.0]))
    assert torch.equal(tiny * 1.0, tiny)                # IEEE arithmetic again


def _goal_dqn(seed, hidden=(16, 16), goal_weight=None):
    import numpy as np

    from hubsgo_ppl.agents.low_level import GoalDQN
    from hubsgo_ppl.agents.settings import GoalDQNConfig

    cfg = GoalDQNConfig(hidden=hidden, batch_size=8, learning_starts=8, grad_clip=0.5, shaping=1.0)
    low = GoalDQN(9, 3, 4, cfg, torch.Generator().manual_seed(seed), np.random.default_rng(seed),
                  potential=lambda obs: -obs[..., :3])
    low.goal_weight = goal_weight
    r = np.random.default_rng(40)
    for _ in range(30):
        low.store(r.random(9).astype(np.float32), int(r.integers(4)), r.random(9).astype(np.float32),
                  r.random(3) < 0.3, r.random(3) < 0.5, bool(r.random() < 0.1))
    return low


@pytest.mark.parametrize("hidden, goal_weight", [((16, 16), None), ((7, 5, 3), torch.tensor([1.0, 0.5, 0.0]))])
def test_the_learners_handwritten_gradients_equal_autograds_to_the_bit(monkeypatch, hidden, goal_weight):
    """GoalDQN's and the high level's TD steps differentiate their MLP without autograd
    (nets.backward); a copy forced onto autograd (forward_saved -> None) takes the same steps."""
    import copy

    import numpy as np

    from hubsgo_ppl.agents import high_level, low_level
    from hubsgo_ppl.agents.high_level import HighLevelDQN
    from hubsgo_ppl.agents.settings import HighLevelConfig

    fast, ref = _goal_dqn(0, hidden, goal_weight), _goal_dqn(0, hidden, goal_weight)
    high = HighLevelDQN(9, 3, HighLevelConfig(hidden=hidden, batch_size=8, learning_starts=8),
                        torch.Generator().manual_seed(1), np.random.default_rng(1))
    r = np.random.default_rng(2)
    for _ in range(20):
        high.store(r.random(9).astype(np.float32), int(r.integers(3)), float(r.random()), r.random(9).astype(np.float32),
                   0.9, r.random(3) < 0.7)
    high_ref = copy.deepcopy(high)
    for _ in range(5):
        got_low, (got_high, _) = fast.update(), high.update(None)
        with monkeypatch.context() as m:
            m.setattr(low_level, "forward_saved", lambda net, x: None)
            m.setattr(high_level, "forward_saved", lambda net, x: None)
            want_low, (want_high, _) = ref.update(), high_ref.update(None)
        assert (got_low, got_high) == (want_low, want_high)
    for a, b in ((fast.net, ref.net), (high.net, high_ref.net)):
        for net_a, net_b in ((a.online, b.online), (a.target, b.target)):
            for (k, va), vb in zip(net_a.state_dict().items(), net_b.state_dict().values()):
                assert torch.equal(va, vb), k
    start = _goal_dqn(0, hidden).q.state_dict()
    assert any(not torch.equal(v, start[k]) for k, v in fast.q.state_dict().items())     # it did learn


def test_backward_refuses_what_it_cannot_differentiate():
    from hubsgo_ppl.agents.nets import forward_saved

    g = torch.Generator().manual_seed(0)
    assert forward_saved(nn.Sequential(nn.Linear(3, 4), nn.Tanh(), nn.Linear(4, 2)), torch.zeros(1, 3)) is None
    out, inputs = forward_saved(mlp(3, [4], 2, g), torch.zeros(5, 3))
    assert out.shape == (5, 2) and [tuple(x.shape) for x in inputs] == [(5, 3), (5, 4)]
