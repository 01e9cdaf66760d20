"""Seeded MLPs: layout, reproducible initialisation from the given generator only, torch's bounds."""

import math

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
