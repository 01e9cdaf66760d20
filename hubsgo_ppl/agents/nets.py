"""Small MLPs with explicitly seeded initialisation (no global torch RNG), and the online/target
network pair of the DQN learners (:class:`TargetNetwork`)."""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import torch
from stable_baselines3.common.utils import polyak_update
from torch import nn

__all__ = ["mlp", "seeded_init_", "TargetNetwork"]


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


class TargetNetwork:
    """An online network, its target copy and the online network's Adam: the plumbing of the DQN
    learners (the high level, the grid low level and HIRO's discrete low level).

    ``make()`` builds one network; it is called twice, online first, so that a seeded ``make`` draws
    the online weights and then the target's (which are then overwritten by the online ones).
    :meth:`step` takes one gradient step on a loss and moves the target ``tau`` of the way towards the
    online network (Polyak averaging, Stable-Baselines3's ``polyak_update``)."""

    def __init__(self, make: Callable[[], nn.Module], lr: float, tau: float, grad_clip: float | None = None):
        self.online = make()
        self.target = make()
        self.target.load_state_dict(self.online.state_dict())
        self.opt = torch.optim.Adam(self.online.parameters(), lr=lr)
        self.tau, self.grad_clip = tau, grad_clip
        self.stacked = False    # the weights and Adam state are views of a stack of seeds' (agents/stacked.py)

    def step(self, loss: torch.Tensor) -> None:
        """One Adam step on ``loss`` (gradients clipped to norm ``grad_clip`` where given), then Polyak."""
        self.opt.zero_grad()
        loss.backward()
        if self.grad_clip is not None:
            nn.utils.clip_grad_norm_(self.online.parameters(), self.grad_clip)
        self.opt.step()
        polyak_update(self.online.parameters(), self.target.parameters(), self.tau)

    def state_dict(self, online: str = "q", target: str = "q_target", opt: str = "opt") -> dict[str, Any]:
        """The three states under the names a learner's checkpoint uses (copies of a stacked network's
        slices, so that a checkpoint holds only its own seed)."""
        s = {online: self.online.state_dict(), target: self.target.state_dict(), opt: self.opt.state_dict()}
        if self.stacked:
            s = _cloned(s)
        return s

    def load_state_dict(self, s: dict[str, Any], online: str = "q", target: str = "q_target", opt: str = "opt") -> None:
        self.online.load_state_dict(s[online])
        self.target.load_state_dict(s[target])
        self.opt.load_state_dict(s[opt])


def _cloned(x: Any) -> Any:
    """``x`` with every tensor in its dicts and lists copied."""
    if isinstance(x, torch.Tensor):
        return x.clone()
    if isinstance(x, dict):
        out = type(x)((k, _cloned(v)) for k, v in x.items())
        if hasattr(x, "_metadata"):     # a module's state_dict: its layout versions
            out._metadata = x._metadata
        return out
    if isinstance(x, list):
        return [_cloned(v) for v in x]
    return x
