"""The TD3 core shared by HIRO (:mod:`.hiro`: its high level and its continuous low level), HIGL
(:mod:`.higl`, HIRO's structure with a landmark term in the high level's actor loss) and the
learned arm low level (:mod:`.td3_her`, GoalTD3 + HER).

TD3 (Fujimoto, van Hoof, Meger 2018): a deterministic actor ``tanh(·)``, twin critics whose minimum
is the target, target policy smoothing, and delayed actor and target updates. The target networks
follow with SB3's Polyak update. Adam and the Polyak update run as one ``_foreach`` operation per step
over all of a module's tensors (torch's multi-tensor Adam), the same floats as the per-tensor loops at a
fraction of their Python overhead (tests/agents/test_td3.py), with subnormal moments flushed to zero
(``nets.flushing_subnormals``). Inputs and outputs are plain tensors: what goes into the networks
(observations, goals, normalisation) is the caller's business.

Actions live either in ``[-1, 1]`` (``scale=None``; GoalTD3 maps them to the env's bounds itself) or
in ``[-scale, scale]`` (HIRO), where the critics see ``a / scale``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from .nets import flushing_subnormals, mlp

__all__ = ["TD3Core", "TD3Step", "NETS"]

#: the four networks, in the order their initial weights are drawn unless told otherwise
NETS = ("actor", "critics", "actor_target", "critics_target")


@dataclass(frozen=True)
class TD3Step:
    """What one TD3 update reports; ``actor_loss`` is None on steps without an actor update."""

    critic_loss: float
    q: float                    # mean Q1 of the minibatch's actions
    actor_loss: float | None


class TD3Core:
    """Actor, twin critics, their targets and optimisers, and the TD3 update.

    Args:
        in_dim, act_dim: network input size and action size.
        hidden: hidden layer sizes of every network.
        generator: draws the initial weights (in ``init_order``: callers that share one generator
            across several learners keep their order, so seeded runs reproduce).
        actor_lr, critic_lr: Adam learning rates.
        tau: Polyak rate of the targets; policy_delay: critic updates per actor update.
        target_noise, target_noise_clip: target policy smoothing, in units of the action range.
        scale: None (actions in [-1, 1]) or the action bound per dimension.
        action_l2: weight of a penalty on the actor's squared actions (None: no penalty term).
        target_range: clip the TD target into this interval (None: no clipping).
    """

    def __init__(self, in_dim: int, act_dim: int, hidden: Sequence[int], generator: torch.Generator, *,
                 actor_lr: float, critic_lr: float, tau: float, policy_delay: int, target_noise: float,
                 target_noise_clip: float, scale: np.ndarray | None = None, action_l2: float | None = None,
                 target_range: tuple[float, float] | None = None, init_order: Sequence[str] = NETS):
        if sorted(init_order) != sorted(NETS):
            raise ValueError(f"init_order must name each of {NETS} once, got {tuple(init_order)}")
        make = {"actor": lambda: mlp(in_dim, hidden, act_dim, generator),
                "critics": lambda: nn.ModuleList([mlp(in_dim + act_dim, hidden, 1, generator) for _ in range(2)])}
        nets = {name: make[name.removesuffix("_target")]() for name in init_order}
        self.actor: nn.Module = nets["actor"]
        self.critics: nn.ModuleList = nets["critics"]
        self.actor_target: nn.Module = nets["actor_target"]
        self.critics_target: nn.ModuleList = nets["critics_target"]
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critics_target.load_state_dict(self.critics.state_dict())
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=actor_lr, foreach=True)
        self.critic_opt = torch.optim.Adam(self.critics.parameters(), lr=critic_lr, foreach=True)
        self.tau, self.policy_delay = tau, policy_delay
        self.target_noise, self.target_noise_clip = target_noise, target_noise_clip
        self.scale = None if scale is None else torch.as_tensor(scale, dtype=torch.float32)
        self.action_l2 = action_l2
        self.target_range = target_range
        self.updates = 0

    # -- networks ------------------------------------------------------------------------------------
    def mu(self, x: torch.Tensor, target: bool = False) -> torch.Tensor:
        """The deterministic action of the actor (or its target)."""
        a = torch.tanh((self.actor_target if target else self.actor)(x))
        return a if self.scale is None else a * self.scale

    def q_values(self, critics: nn.ModuleList, x: torch.Tensor, a: torch.Tensor) -> list[torch.Tensor]:
        xa = torch.cat([x, a if self.scale is None else a / self.scale], -1)
        return [net(xa).squeeze(-1) for net in critics]

    # -- learning ------------------------------------------------------------------------------------
    def update(self, x: torch.Tensor, a: torch.Tensor, r: torch.Tensor, x_next: torch.Tensor,
               discount: torch.Tensor | float, noise: torch.Tensor,
               actor_extra: Callable[[torch.Tensor], torch.Tensor] | None = None) -> TD3Step:
        """One TD3 step: ``y = r + discount * min_i Q_i'(x', μ'(x') + ε)``; the actor and the targets
        every ``policy_delay`` steps. ``noise`` is standard normal, drawn by the caller's generator.
        ``actor_extra``: a term added to the actor's loss, a function of the actor's actions ``μ(x)``
        (HIGL's landmark loss), called only on the steps that update the actor."""
        with torch.no_grad():
            eps = (noise * self.target_noise).clamp(-self.target_noise_clip, self.target_noise_clip)
            if self.scale is None:
                a_next = (self.mu(x_next, target=True) + eps).clamp(-1.0, 1.0)
            else:
                a_next = torch.max(torch.min(self.mu(x_next, target=True) + eps * self.scale, self.scale),
                                   -self.scale)
            y = r + discount * torch.min(*self.q_values(self.critics_target, x_next, a_next))
            if self.target_range is not None:
                y = y.clamp(*self.target_range)
        q1, q2 = self.q_values(self.critics, x, a)
        critic_loss = F.mse_loss(q1, y) + F.mse_loss(q2, y)
        self.critic_opt.zero_grad()
        critic_loss.backward()
        with flushing_subnormals():     # as the DQN learners' Adam (agents/nets.py)
            self.critic_opt.step()
        self.updates += 1
        actor_loss = None
        if self.updates % self.policy_delay == 0:
            pi = self.mu(x)
            loss = -self.q_values(self.critics[:1], x, pi)[0].mean()
            if self.action_l2 is not None:
                loss = loss + self.action_l2 * pi.pow(2).mean()
            if actor_extra is not None:
                loss = loss + actor_extra(pi)
            self.actor_opt.zero_grad()
            loss.backward()
            with flushing_subnormals():
                self.actor_opt.step()
            _polyak(self.actor, self.actor_target, self.tau)
            _polyak(self.critics, self.critics_target, self.tau)
            actor_loss = loss.item()
        return TD3Step(critic_loss=critic_loss.item(), q=q1.mean().item(), actor_loss=actor_loss)

    # -- checkpointing -------------------------------------------------------------------------------
    #: the state keys, by attribute; a caller may store them under other names (``keys``)
    STATE = ("actor", "actor_target", "critics", "critics_target", "actor_opt", "critic_opt")

    def state_dict(self, keys: dict[str, str] | None = None) -> dict[str, Any]:
        """The networks' and optimisers' states under ``keys[attribute]`` (default: the attribute
        names, in :data:`STATE` order); the update counter is the caller's to store."""
        keys = keys or {k: k for k in self.STATE}
        return {name: getattr(self, attr).state_dict() for attr, name in keys.items()}

    def load_state_dict(self, state: dict[str, Any], keys: dict[str, str] | None = None) -> None:
        keys = keys or {k: k for k in self.STATE}
        for attr, name in keys.items():
            getattr(self, attr).load_state_dict(state[name])
        for opt in (self.actor_opt, self.critic_opt):      # a state saved with the per-tensor loop: the same floats
            for group in opt.param_groups:
                group["foreach"] = True


@torch.no_grad()
def _polyak(online: nn.Module, target: nn.Module, tau: float) -> None:
    """SB3's ``polyak_update`` (``target = (1 - tau) * target + tau * online``, in place), its two
    operations each applied to every tensor at once."""
    targets = list(target.parameters())
    torch._foreach_mul_(targets, 1 - tau)
    torch._foreach_add_(targets, list(online.parameters()), alpha=tau)
