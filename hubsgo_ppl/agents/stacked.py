"""Several seeds' GoalDQN low levels trained together: their networks stacked along a leading seed
dimension, acted and updated with batched matrix products (one ``bmm`` per layer for every seed).

:class:`StackedNets` takes the :class:`~.nets.TargetNetwork` of each seed (ReLU MLPs of one shape) and
moves their online and target weights and their Adam moments into stacked tensors ``(S, ...)``; each
seed's own modules and optimiser state are then views of its slice, so that the seed's checkpoint,
its evaluation episodes and every reader of the run folder see the same numbers as the stacked update
writes. Adam is elementwise, so one stacked step is, in its arithmetic, each seed's own Adam step;
gradient clipping is by each seed's own norm. A step can take any subset of the seeds (a seed whose
budget is spent, or whose updates fall on other env steps after a resume).

:class:`StackedGoalDQN` is the low level's TD loss (``GoalDQN.update``) over the stack: each seed
samples its own minibatch from its own replay with its own generator.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from torch import nn

from .low_level import GoalDQN
from .nets import TargetNetwork, flushing_subnormals

__all__ = ["StackedNets", "StackedGoalDQN"]


def _linears(net: nn.Module) -> list[nn.Linear]:
    return [m for m in net.modules() if isinstance(m, nn.Linear)]


def stacked_forward(params: Sequence[torch.Tensor], x: torch.Tensor) -> torch.Tensor:
    """The MLP of ``nets.mlp`` for every seed: ``params`` alternate weights (S, out, in) and biases
    (S, out); ``x`` is (S, B, in)."""
    n = len(params) // 2
    for i in range(n):
        w, b = params[2 * i], params[2 * i + 1]
        x = torch.baddbmm(b.unsqueeze(1), x, w.transpose(1, 2))
        if i < n - 1:
            x = torch.relu(x)
    return x


class StackedNets:
    """The online networks, target networks and Adam states of several :class:`TargetNetwork` s."""

    def __init__(self, nets: Sequence[TargetNetwork]):
        self.nets = list(nets)
        group = nets[0].opt.param_groups[0]
        self.lr, (self.beta1, self.beta2), self.eps = group["lr"], group["betas"], group["eps"]
        bad = [g for n in nets for g in n.opt.param_groups
               if (g["lr"], g["betas"], g["eps"]) != (self.lr, (self.beta1, self.beta2), self.eps)
               or g.get("weight_decay") or g.get("amsgrad") or g.get("maximize")]
        if bad or any((n.tau, n.grad_clip) != (nets[0].tau, nets[0].grad_clip) for n in nets):
            raise ValueError("stacked networks need the same optimiser settings, Polyak rate and clipping")
        self.tau, self.grad_clip = nets[0].tau, nets[0].grad_clip
        online = [[p for m in _linears(n.online) for p in (m.weight, m.bias)] for n in nets]
        target = [[p for m in _linears(n.target) for p in (m.weight, m.bias)] for n in nets]
        self.params = [torch.stack([ps[j].detach() for ps in online]).contiguous() for j in range(len(online[0]))]
        self.targets = [torch.stack([ps[j].detach() for ps in target]).contiguous() for j in range(len(target[0]))]
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        self.steps = torch.zeros(len(self.params), len(nets))     # Adam's step count of each parameter, seed
        for k, net in enumerate(nets):
            for j, p in enumerate(online[k]):
                st = net.opt.state.get(p)
                if st:
                    self.exp_avg[j][k] = st["exp_avg"]
                    self.exp_avg_sq[j][k] = st["exp_avg_sq"]
                    self.steps[j, k] = float(st["step"])
        for k, net in enumerate(nets):      # each seed's modules and Adam state: views of its slice
            for j, p in enumerate(online[k]):
                p.data = self.params[j][k]
                net.opt.state[p] = {"step": self.steps[j, k], "exp_avg": self.exp_avg[j][k],
                                    "exp_avg_sq": self.exp_avg_sq[j][k]}
            for j, p in enumerate(target[k]):
                p.data = self.targets[j][k]
            net.stacked = True

    @torch.no_grad()
    def values(self, obs: torch.Tensor) -> torch.Tensor:
        """(S, B, out) online values of every seed, ``obs`` (S, B, in)."""
        return stacked_forward(self.params, obs)

    def step(self, idx: list[int], loss_fn) -> torch.Tensor:
        """One gradient step of the seeds ``idx`` on ``loss_fn(online params, target params)`` -> (s,)
        per-seed losses; their Adam steps and Polyak updates. Returns the per-seed losses."""
        full = idx == list(range(len(self.nets)))
        sel = slice(None) if full else torch.as_tensor(idx)
        leaves = [(p if full else p[sel]).detach().requires_grad_() for p in self.params]
        with torch.no_grad():
            targets = self.targets if full else [t[sel] for t in self.targets]
        losses = loss_fn(leaves, targets)
        losses.sum().backward()
        grads = [p.grad for p in leaves]
        with torch.no_grad():
            if self.grad_clip is not None:      # torch.nn.utils.clip_grad_norm_, per seed
                norms = torch.stack([torch.linalg.vector_norm(g.flatten(1), dim=1) for g in grads], dim=1)
                total = torch.linalg.vector_norm(norms, dim=1)
                coef = torch.clamp(self.grad_clip / (total + 1e-6), max=1.0)
                for g in grads:
                    g.mul_(coef.view(-1, *([1] * (g.dim() - 1))))
            with flushing_subnormals():     # as TargetNetwork's Adam (agents/nets.py)
                if full:
                    self._adam_full(grads)
                else:
                    for j, (p, g) in enumerate(zip(self.params, grads)):
                        self._adam(j, p, g, sel)
            for p, t in zip(self.params, self.targets):     # Polyak (SB3's polyak_update)
                if full:
                    t.mul_(1 - self.tau)
                    torch.add(t, p, alpha=self.tau, out=t)
                else:
                    t[sel] = t[sel].mul_(1 - self.tau).add_(p[sel], alpha=self.tau)
        return losses.detach()

    def _corrections(self, steps: torch.Tensor, like: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Adam's -step size and sqrt of the second bias correction per seed, shaped to broadcast on ``like``."""
        n = steps.double().numpy()
        shape = (-1, *([1] * (like.dim() - 1)))
        step_size = torch.as_tensor(-(self.lr / (1 - self.beta1 ** n)), dtype=like.dtype).view(shape)
        bc2_sqrt = torch.as_tensor(np.sqrt(1 - self.beta2 ** n), dtype=like.dtype).view(shape)
        return step_size, bc2_sqrt

    def _adam_full(self, grads: list[torch.Tensor]) -> None:
        """torch.optim.Adam's single-tensor step of every seed, every parameter."""
        self.steps += 1
        m, v = self.exp_avg, self.exp_avg_sq
        torch._foreach_lerp_(m, grads, 1 - self.beta1)
        torch._foreach_mul_(v, self.beta2)
        torch._foreach_addcmul_(v, grads, grads, 1 - self.beta2)
        corr = [self._corrections(self.steps[j], p) for j, p in enumerate(self.params)]
        denom = torch._foreach_sqrt(v)
        torch._foreach_div_(denom, [c[1] for c in corr])
        torch._foreach_add_(denom, self.eps)
        update = torch._foreach_mul(m, [c[0] for c in corr])
        torch._foreach_div_(update, denom)
        torch._foreach_add_(self.params, update)

    def _adam(self, j: int, p: torch.Tensor, g: torch.Tensor, sel) -> None:
        """torch.optim.Adam's single-tensor step of parameter j for the seeds ``sel``."""
        steps = self.steps[j, sel] + 1
        self.steps[j, sel] = steps
        m, v = self.exp_avg[j][sel], self.exp_avg_sq[j][sel]
        m.lerp_(g, 1 - self.beta1)
        v.mul_(self.beta2).addcmul_(g, g, value=1 - self.beta2)
        step_size, bc2_sqrt = self._corrections(steps, p)
        denom = (v.sqrt() / bc2_sqrt).add_(self.eps)
        p[sel] = p[sel] + (m * step_size) / denom
        self.exp_avg[j][sel] = m
        self.exp_avg_sq[j][sel] = v


class StackedGoalDQN:
    """The GoalDQN low levels of several seeds: batched greedy actions and batched TD steps."""

    def __init__(self, lows: Sequence[GoalDQN]):
        self.lows = list(lows)
        shapes = {(lw.n_goals, lw.n_actions, lw.cfg.batch_size, lw.cfg.gamma, lw.cfg.shaping) for lw in lows}
        if len(shapes) != 1:
            raise ValueError("the seeds' low levels differ in shape or settings; they cannot be stacked")
        self.nets = StackedNets([lw.net for lw in lows])
        self.n_goals, self.n_actions = lows[0].n_goals, lows[0].n_actions
        self.obs_dim = self.nets.params[0].shape[-1]

    def greedy(self, requests: dict[int, tuple[np.ndarray, int]]) -> dict[int, int]:
        """argmax_a Q_k(obs, g, a) for each seed k of ``requests`` ({k: (obs, g)})."""
        x = torch.zeros(len(self.lows), 1, self.obs_dim)
        for k, (obs, _) in requests.items():
            x[k, 0] = torch.as_tensor(obs, dtype=torch.float32)
        q = self.nets.values(x).view(len(self.lows), self.n_goals, self.n_actions)
        return {k: int(q[k, g].argmax()) for k, (_, g) in requests.items()}

    def update(self, idx: list[int]) -> list[dict[str, float]]:
        """One TD step (``GoalDQN.update``) of the seeds ``idx``, each on its own minibatch."""
        lows = [self.lows[k] for k in idx]
        bs = [lw.buffer.sample(lw.cfg.batch_size) for lw in lows]
        b = {key: torch.stack([x[key] for x in bs]) for key in bs[0]}
        cfg, N, A = lows[0].cfg, self.n_goals, self.n_actions
        before, after = b["before"].bool(), b["after"].bool()
        reward = (after & ~before).float()                                      # (s, B, N)
        done = (reward > 0) | b["terminated"].bool()[..., None]
        if lows[0].potential is not None:
            phi = torch.stack([lw.potential(x["obs"]) for lw, x in zip(lows, bs)])
            phi_next = torch.stack([lw.potential(x["next_obs"]) for lw, x in zip(lows, bs)])
            reward = reward + cfg.shaping * (cfg.gamma * (~done).float() * phi_next - phi)
        weight = (~before).float()
        if any(lw.goal_weight is not None for lw in lows):
            gw = torch.stack([torch.ones(N) if lw.goal_weight is None else lw.goal_weight for lw in lows])
            weight = weight * gw[:, None, :]
        s, B = len(lows), before.shape[1]

        def loss_fn(online, target):
            with torch.no_grad():
                q_next = stacked_forward(target, b["next_obs"]).view(s, B, N, A).max(-1).values
                y = reward + cfg.gamma * (~done).float() * q_next
            q = stacked_forward(online, b["obs"]).view(s, B, N, A)
            q_a = q.gather(3, b["action"][..., None, None].expand(-1, -1, N, 1)).squeeze(3)
            return (weight * (q_a - y).pow(2)).sum((1, 2)) / weight.sum((1, 2)).clamp_min(1.0)

        losses = self.nets.step(idx, loss_fn).tolist()
        return [{"low/td_loss": x} for x in losses]
