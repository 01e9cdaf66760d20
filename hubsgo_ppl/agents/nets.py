"""Small MLPs with explicitly seeded initialisation (no global torch RNG), and the online/target
network pair of the DQN learners (:class:`TargetNetwork`)."""

from __future__ import annotations

import math
from typing import Any, Callable, Sequence

import torch
from torch import nn

__all__ = ["mlp", "seeded_init_", "TargetNetwork", "forward"]


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


def forward(net: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """``net(x)`` for an :func:`mlp`, the same operations without the modules' call machinery (it runs
    a few times per env step); any other module is called as usual."""
    layers = net.__dict__.get("_plain_layers")
    if layers is None:
        mods = list(net) if isinstance(net, nn.Sequential) else []
        plain = bool(mods) and all(type(m) in (nn.Linear, nn.ReLU) for m in mods) and not (
            net._forward_hooks or net._forward_pre_hooks or any(m._forward_hooks or m._forward_pre_hooks for m in mods))
        layers = [m if type(m) is nn.Linear else None for m in mods] if plain else []
        net.__dict__["_plain_layers"] = layers
    if not layers:
        return net(x)
    for m in layers:
        x = torch.relu(x) if m is None else torch._C._nn.linear(x, m.weight, m.bias)
    return x


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
        self.stacked = False
        self._online_params: tuple[nn.Module, list[torch.Tensor]] | None = None
        self._target_cache: tuple[nn.Module, list[torch.Tensor]] | None = None    # the weights and Adam state are views of a stack of seeds' (agents/stacked.py)

    def step(self, loss: torch.Tensor) -> None:
        """One Adam step on ``loss`` (gradients clipped to norm ``grad_clip`` where given), then Polyak.

        The same arithmetic as ``opt.zero_grad(); loss.backward(); clip_grad_norm_(...); opt.step();
        polyak_update(...)`` with torch's default (single-tensor) Adam, to the bit, in fewer Python calls
        (tests/agents/test_nets.py compares the two)."""
        params = self._params()
        for p in params:
            p.grad = None
        loss.backward()
        with torch.no_grad():
            grads = [p.grad for p in params]
            if self.grad_clip is not None:      # nn.utils.clip_grad_norm_ (its foreach path)
                total = torch.linalg.vector_norm(torch.stack(torch._foreach_norm(grads, 2.0)), 2.0)
                torch._foreach_mul_(grads, torch.clamp(float(self.grad_clip) / (total + 1e-6), max=1.0))
            self._adam(params, grads)
            targets = self._target_params()     # stable_baselines3's polyak_update
            torch._foreach_mul_(targets, 1 - self.tau)
            torch._foreach_add_(targets, params, alpha=self.tau)

    def _params(self) -> list[torch.Tensor]:
        if self._online_params is None or self._online_params[0] is not self.online:
            self._online_params = (self.online, list(self.online.parameters()))
        return self._online_params[1]

    def _target_params(self) -> list[torch.Tensor]:
        if self._target_cache is None or self._target_cache[0] is not self.target:
            self._target_cache = (self.target, list(self.target.parameters()))
        return self._target_cache[1]

    def _adam(self, params: list[torch.Tensor], grads: list[torch.Tensor]) -> None:
        """torch.optim.Adam's step (no weight decay, amsgrad or maximize: the learners' settings), as
        its single-tensor implementation computes it, on the optimiser's own state."""
        group = self.opt.param_groups[0]
        if (type(self.opt) is not torch.optim.Adam or len(self.opt.param_groups) != 1 or group.get("weight_decay") or group.get("amsgrad") or group.get("maximize")
                or group.get("decoupled_weight_decay")):
            self.opt.step()
            return
        lr, (beta1, beta2), eps = float(group["lr"]), group["betas"], group["eps"]
        state = self.opt.state
        for p in params:
            if not state[p]:
                state[p]["step"] = torch.tensor(0.0, dtype=torch.float32)
                state[p]["exp_avg"] = torch.zeros_like(p, memory_format=torch.preserve_format)
                state[p]["exp_avg_sq"] = torch.zeros_like(p, memory_format=torch.preserve_format)
        sts = [state[p] for p in params]
        steps = [st["step"] for st in sts]
        exp_avgs = [st["exp_avg"] for st in sts]
        exp_avg_sqs = [st["exp_avg_sq"] for st in sts]
        torch._foreach_add_(steps, 1)
        torch._foreach_lerp_(exp_avgs, grads, 1 - beta1)
        torch._foreach_mul_(exp_avg_sqs, beta2)
        torch._foreach_addcmul_(exp_avg_sqs, grads, grads, 1 - beta2)
        step = [float(t.item()) for t in steps]
        step_size = [-(lr / (1 - beta1 ** n)) for n in step]
        bc2_sqrt = [(1 - beta2 ** n) ** 0.5 for n in step]
        denom = torch._foreach_sqrt(exp_avg_sqs)
        torch._foreach_div_(denom, bc2_sqrt)
        torch._foreach_add_(denom, eps)
        torch._foreach_addcdiv_(params, exp_avgs, denom, step_size)

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
