"""Several seeds' GoalDQN low levels trained together: their networks stacked along a leading seed
dimension, acted and updated with batched matrix products (one ``bmm`` per layer for every seed).

:class:`StackedNets` takes the :class:`~.nets.TargetNetwork` of each seed (ReLU MLPs of one shape) and
moves their online and target weights and their Adam moments into buffers ``(S, P)`` (seeds x every
parameter's numbers), whose column blocks are the stacked layers ``(S, ...)``; each seed's own modules
and optimiser state are then views of its row, so that the seed's checkpoint,
its evaluation episodes and every reader of the run folder see the same numbers as the stacked update
writes. Adam is elementwise, so one stacked step is, in its arithmetic, each seed's own Adam step;
gradient clipping is by each seed's own norm. A step can take any subset of the seeds (a seed whose
budget is spent, or whose updates fall on other env steps after a resume).

:class:`StackedGoalDQN` is the low level's TD loss (``GoalDQN.update``) over the stack: each seed
samples its own minibatch from its own replay with its own generator, and the gradients are taken by
hand (:func:`stacked_backward`, autograd's own operations, as ``nets.backward`` for one seed).
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


def stacked_forward_saved(params: Sequence[torch.Tensor], x: torch.Tensor) -> tuple[torch.Tensor, list[torch.Tensor]]:
    """:func:`stacked_forward` and the input of each layer, which :func:`stacked_backward` needs."""
    n = len(params) // 2
    inputs = []
    for i in range(n):
        w, b = params[2 * i], params[2 * i + 1]
        inputs.append(x)
        x = torch.baddbmm(b.unsqueeze(1), x, w.transpose(1, 2))
        if i < n - 1:
            x = torch.relu(x)
    return x, inputs


def stacked_backward(params: Sequence[torch.Tensor], inputs: list[torch.Tensor], grad: torch.Tensor) -> list[torch.Tensor]:
    """The gradient of every parameter of :func:`stacked_forward` given the loss's gradient at its output,
    with the operations autograd runs for ``baddbmm`` and ``relu`` (nets.backward does the same for one
    seed), each weight's gradient contiguous as autograd leaves it."""
    n = len(params) // 2
    grads: list[torch.Tensor] = []
    for i in range(n - 1, -1, -1):
        w, x = params[2 * i], inputs[i]
        g_w = x.transpose(1, 2).bmm(grad).transpose(1, 2).contiguous()    # baddbmm's batch2 gradient, transposed back
        g_b = grad.sum([1], keepdim=True).squeeze(1)                        # the engine's sum_to of the broadcast bias
        grads += [g_b, g_w]
        if i > 0:
            grad = torch.ops.aten.threshold_backward(grad.bmm(w), x, 0)   # baddbmm's batch1 gradient, then ReLU's
    return grads[::-1]


class StackedNets:
    """The online networks, target networks and Adam states of several :class:`TargetNetwork` s.

    Each of the four is one buffer ``(S, P)`` (seeds x every parameter's numbers, layer after layer):
    a layer's stacked weights are views ``(S, out, in)`` of its columns, and each seed's own parameters
    and Adam state are views of its row, so that Adam and Polyak run as one operation per buffer."""

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
        S = len(nets)
        self.shapes = [tuple(p.shape) for p in online[0]]
        sizes = [p.numel() for p in online[0]]
        self.offsets = [sum(sizes[:j]) for j in range(len(sizes) + 1)]

        def buffer(rows: list[list[torch.Tensor]]) -> torch.Tensor:
            return torch.stack([torch.cat([t.detach().reshape(-1) for t in row]) for row in rows])

        def views(flat: torch.Tensor) -> list[torch.Tensor]:
            return [flat[:, a:b].view(S, *shape) for a, b, shape in zip(self.offsets, self.offsets[1:], self.shapes)]

        zeros = [[torch.zeros_like(p) for p in row] for row in online]
        self.flat = buffer(online)
        self.flat_target = buffer(target)
        self.flat_m = buffer([[net.opt.state[p]["exp_avg"] if net.opt.state.get(p) else z for p, z in zip(row, zr)]
                              for net, row, zr in zip(nets, online, zeros)])
        self.flat_v = buffer([[net.opt.state[p]["exp_avg_sq"] if net.opt.state.get(p) else z for p, z in zip(row, zr)]
                              for net, row, zr in zip(nets, online, zeros)])
        self.params, self.targets = views(self.flat), views(self.flat_target)
        self.exp_avg, self.exp_avg_sq = views(self.flat_m), views(self.flat_v)
        self.steps = torch.zeros(len(self.params), S)     # Adam's step count of each parameter, seed
        for k, net in enumerate(nets):
            for j, p in enumerate(online[k]):
                st = net.opt.state.get(p)
                if st:
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

    def rows(self, idx: list[int]) -> slice | torch.Tensor:
        """The index of the seeds ``idx`` in the stack: every row as a view, or a subset's rows."""
        return slice(None) if idx == list(range(len(self.nets))) else torch.as_tensor(idx)

    @torch.no_grad()
    def apply(self, idx: list[int], grads: list[torch.Tensor]) -> None:
        """Clipping, Adam and Polyak for the seeds ``idx`` given their gradients, one (s, ...) tensor per
        parameter (contiguous, as autograd leaves them)."""
        sel = self.rows(idx)
        full = isinstance(sel, slice)
        s = len(idx)
        if self.grad_clip is not None:      # torch.nn.utils.clip_grad_norm_, per seed
            norms = torch.stack([torch.linalg.vector_norm(g.flatten(1), dim=1) for g in grads], dim=1)
            total = torch.linalg.vector_norm(norms, dim=1)
            coef = torch.clamp(self.grad_clip / (total + 1e-6), max=1.0)
        g = torch.cat([x.reshape(s, -1) for x in grads], dim=1)
        if self.grad_clip is not None:
            g.mul_(coef.view(-1, 1))
        with flushing_subnormals():         # as TargetNetwork's Adam (agents/nets.py)
            if full:
                self._adam(g, self.flat, self.flat_m, self.flat_v, self.steps)
                self.flat_target.mul_(1 - self.tau)      # Polyak (SB3's polyak_update)
                torch.add(self.flat_target, self.flat, alpha=self.tau, out=self.flat_target)
            else:
                p, m, v, steps = self.flat[sel], self.flat_m[sel], self.flat_v[sel], self.steps[:, sel]
                self._adam(g, p, m, v, steps)
                self.flat[sel], self.flat_m[sel], self.flat_v[sel], self.steps[:, sel] = p, m, v, steps
                self.flat_target[sel] = self.flat_target[sel].mul_(1 - self.tau).add_(p, alpha=self.tau)

    def _adam(self, g: torch.Tensor, p: torch.Tensor, m: torch.Tensor, v: torch.Tensor, steps: torch.Tensor) -> None:
        """torch.optim.Adam's single-tensor step, in place, of the seeds' rows ``p`` (s, P) with their
        moments and step counts (parameters, s)."""
        steps += 1
        n = steps.double().numpy()
        if not (n == n[:1]).all():      # a parameter whose step count differs from its seed's others
            raise RuntimeError("a seed's parameters have taken different numbers of Adam steps")
        n = n[0]
        step_size = torch.as_tensor(-(self.lr / (1 - self.beta1 ** n)), dtype=p.dtype).view(-1, 1)
        bc2_sqrt = torch.as_tensor(np.sqrt(1 - self.beta2 ** n), dtype=p.dtype).view(-1, 1)
        m.lerp_(g, 1 - self.beta1)
        v.mul_(self.beta2).addcmul_(g, g, value=1 - self.beta2)
        denom = (v.sqrt() / bc2_sqrt).add_(self.eps)
        p.add_((m * step_size) / denom)


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
        before, after = b["before"], b["after"]
        reward = (after & ~before).float()                                      # (s, B, N)
        done = (reward > 0) | b["terminated"][..., None]
        going = (~done).float()
        if lows[0].potential is not None:
            phi = torch.stack([lw.potential(x["obs"]) for lw, x in zip(lows, bs)])
            phi_next = torch.stack([lw.potential(x["next_obs"]) for lw, x in zip(lows, bs)])
            reward = reward + cfg.shaping * (cfg.gamma * going * phi_next - phi)
        weight = (~before).float()
        if any(lw.goal_weight is not None for lw in lows):
            gw = torch.stack([torch.ones(N) if lw.goal_weight is None else lw.goal_weight for lw in lows])
            weight = weight * gw[:, None, :]
        s, B = len(lows), before.shape[1]
        nets = self.nets
        sel = nets.rows(idx)
        online = [p[sel] for p in nets.params]
        target = [t[sel] for t in nets.targets]
        with torch.no_grad():               # the loss, and its gradient as autograd computes it
            q_next = stacked_forward(target, b["next_obs"]).view(s, B, N, A).max(-1).values
            y = reward + cfg.gamma * going * q_next
            out, inputs = stacked_forward_saved(online, b["obs"])
            q = out.view(s, B, N, A)
            index = b["action"][..., None, None].expand(-1, -1, N, 1)
            diff = q.gather(3, index).squeeze(3) - y
            denom = weight.sum((1, 2)).clamp_min(1.0)
            losses = (weight * diff.pow(2)).sum((1, 2)) / denom
            grad = (torch.ones_like(losses) / denom)[:, None, None].expand_as(weight) * weight
            grad = grad * (2.0 * diff.pow(1.0))
            grad_q = torch.zeros_like(q).scatter_add_(3, index, grad.unsqueeze(3)).view_as(out)
            nets.apply(idx, stacked_backward(online, inputs, grad_q))
        return [{"low/td_loss": x} for x in losses.tolist()]
