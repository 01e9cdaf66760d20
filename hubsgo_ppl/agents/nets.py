"""Small MLPs with explicitly seeded initialisation (no global torch RNG)."""

from __future__ import annotations

import math
from typing import Sequence

import torch
from torch import nn

__all__ = ["mlp", "seeded_init_"]


def mlp(in_dim: int, hidden: Sequence[int], out_dim: int, generator: torch.Generator) -> nn.Sequential:
    """ReLU MLP whose weights are drawn from ``generator`` (PyTorch's default init uses the global RNG)."""
    layers: list[nn.Module] = []
    last = in_dim
    for h in hidden:
        layers += [nn.Linear(last, h), nn.ReLU()]
        last = h
    layers.append(nn.Linear(last, out_dim))
    net = nn.Sequential(*layers)
    seeded_init_(net, generator)
    return net


@torch.no_grad()
def seeded_init_(module: nn.Module, generator: torch.Generator) -> nn.Module:
    """Kaiming-uniform-like init of every Linear layer (same bounds as torch's default), from ``generator``."""
    for m in module.modules():
        if isinstance(m, nn.Linear):
            bound = 1.0 / math.sqrt(m.in_features)
            m.weight.uniform_(-bound, bound, generator=generator)
            m.bias.uniform_(-bound, bound, generator=generator)
    return module
