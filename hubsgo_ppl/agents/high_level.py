"""The high level: a DQN Q(s, g; θ) over the candidate sub-goals (Sec. 3.2).

Its TD target bootstraps over an allowed set, Eq. 2:
``y = r + γ^k Q(s', g'; θ⁻)`` over g' ∈ M, with M = (Ĝt for HUBS-GO, G0 for h-DQN) ∩ not-yet-achieved.
The same minibatch, as a :class:`~hubsgo_ppl.infer.tdbatch.TDBatch`, goes to the filter, and so to the
critic's update (Algorithm 1, lines 9-11).

The high level's target and the critic's TD residuals share the minibatch but not the bootstrap, on
purpose:

- The high level (:meth:`HighLevelDQN.update`) trains on a double-Q target (``double_q``, the default):
  g' is the online network's argmax over M, valued by the target network, which reduces the max
  operator's overestimation. When Ĝt ∩ not-yet-achieved is empty, M falls back to G0 ∩
  not-yet-achieved, so the high level's own learning never stalls on an empty filtered set.
- A TD likelihood of the critic (Eq. 4; :meth:`TDBatch.residuals`, i.e.
  :func:`~hubsgo_ppl.infer.tdbatch.td_residuals`) scores candidate *sets* G(w):
  ``y_G(w) = r + γ^k max_{g' ∈ G(w) ∩ available} Q(s', g'; θ⁻)``, a plain max of the target network,
  and an empty set bootstraps 0. A set must be judged by the value it allows, and a set that allows
  nothing is worth 0; falling back to G0 there would give the empty set the value of the whole
  catalogue.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable

import numpy as np
import torch

from ..infer.tdbatch import TDBatch
from .buffers import ReplayBuffer
from .nets import TargetNetwork, backward, forward, forward_saved, mlp
from .settings import HighLevelConfig

__all__ = ["HighLevelConfig", "HighLevelBatch", "HighLevelDQN", "masked_max"]


def masked_max(values: torch.Tensor, mask: torch.Tensor, empty: float = 0.0) -> torch.Tensor:
    """max over the last dim where ``mask``; ``empty`` where the mask is all False. Torch ops only."""
    neg = torch.finfo(values.dtype).min
    m = torch.where(mask, values, torch.full_like(values, neg)).max(dim=-1).values
    return torch.where(mask.any(dim=-1), m, torch.full_like(m, empty))


# The high-level minibatch handed to the filter is the critic's own TDBatch (Eq. 2, with the
# not-yet-achieved mask as ``available``): the critic's set-conditioned residuals are computed only in
# TDBatch.residuals / td_residuals. The high level's own double-Q target (update below) is a different
# quantity; the module docstring says why.
HighLevelBatch = TDBatch


class HighLevelDQN:
    """Q(s, g) learner with ε-greedy selection restricted to an allowed set."""

    def __init__(self, obs_dim: int, n_goals: int, config: HighLevelConfig,
                 generator: torch.Generator, rng: np.random.Generator):
        self.cfg = config
        self.n_goals = n_goals
        self.rng = rng
        self.net = TargetNetwork(partial(mlp, obs_dim, config.hidden, n_goals, generator), config.lr,
                                 config.target_tau, config.grad_clip)
        self.q, self.q_target, self.opt = self.net.online, self.net.target, self.net.opt
        self.buffer = ReplayBuffer(config.buffer_size, rng, dtypes={"goal": np.int64, "available": bool},
                                   obs=(obs_dim,), goal=(), reward=(), next_obs=(obs_dim,),
                                   discount=(), available=(n_goals,))
        self.updates = 0

    @torch.no_grad()
    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """(..., N) values of every sub-goal."""
        return forward(self.q, torch.as_tensor(obs, dtype=torch.float32)).numpy()

    def select(self, obs: np.ndarray, allowed: np.ndarray, explore_eps: float) -> int:
        """ε-greedy over ``allowed`` (Sec. 3.4: g_t = argmax_{g' ∈ Ĝt | G0} Q(s_t, g'))."""
        choices = np.flatnonzero(allowed)
        if choices.size == 0:
            raise ValueError("the high level was given an empty allowed set")
        if self.rng.random() < explore_eps:
            return int(self.rng.choice(choices))
        q = self.q_values(obs)
        return int(choices[np.argmax(q[choices])])

    def store(self, obs, goal, reward, next_obs, discount, available) -> None:
        self.buffer.add(obs=obs, goal=goal, reward=reward, next_obs=next_obs, discount=discount,
                        available=available)

    @property
    def first_update(self) -> int:
        """The stored transitions the first update waits for."""
        return max(self.cfg.learning_starts, self.cfg.batch_size)

    def ready(self) -> bool:
        return len(self.buffer) >= self.first_update

    def update(self, target_mask: torch.Tensor | Callable[[torch.Tensor], Any] | None
               ) -> tuple[dict[str, float], HighLevelBatch]:
        """One TD step with targets over ``available ∩ target_mask`` (Eq. 2); returns stats and the batch.

        ``target_mask`` is None (G0), a bool mask (N,) or (B, N), or a callable that maps the minibatch's
        achieved sub-goals at s' (B, N) to such a mask (Ĝt given what each s' has achieved)."""
        b = self.buffer.sample(self.cfg.batch_size)
        avail = b["available"].bool()
        if callable(target_mask):
            target_mask = target_mask(~avail)
        with torch.no_grad():
            q_next_t = forward(self.q_target, b["next_obs"])
            mask = avail if target_mask is None else avail & torch.as_tensor(target_mask).bool()
            mask = torch.where(mask.any(-1, keepdim=True), mask, avail)   # empty Ĝt ∩ avail: fall back to G0
            if self.cfg.double_q:
                q_next_online = forward(self.q, b["next_obs"])
                neg = torch.finfo(q_next_online.dtype).min
                a_star = torch.where(mask, q_next_online, torch.full_like(q_next_online, neg)).argmax(-1)
                boot = q_next_t.gather(1, a_star[:, None]).squeeze(1)
                boot = torch.where(mask.any(-1), boot, torch.zeros_like(boot))
            else:
                boot = masked_max(q_next_t, mask)
            y = b["reward"] + b["discount"] * boot
        index = b["goal"][:, None]
        saved = forward_saved(self.q, b["obs"])
        if saved is None:                   # a network backward() does not cover: autograd
            q_taken = forward(self.q, b["obs"]).gather(1, index).squeeze(1)
            loss = 0.5 * (y - q_taken).pow(2).mean()            # Eq. 2
            self.net.step(loss)
        else:
            with torch.no_grad():           # the same loss, and its gradient as autograd computes it
                out, inputs = saved
                q_taken = out.gather(1, index).squeeze(1)
                diff = y - q_taken
                loss = 0.5 * diff.pow(2).mean()                 # Eq. 2
                grad = (torch.ones_like(loss) * 0.5).expand_as(diff) / diff.numel()     # d loss / d diff^2
                grad = -(grad * (2.0 * diff.pow(1.0)))                                     # ... / d q_taken
                grad_q = torch.zeros_like(out).scatter_add_(1, index, grad.unsqueeze(1))
                self.net.apply(backward(self.q, inputs, grad_q))
        self.updates += 1
        batch = HighLevelBatch(q_taken=q_taken.detach(), q_next=q_next_t, reward=b["reward"],
                               discount=b["discount"], available=avail)
        return {"high/td_loss": loss.item()}, batch

    def state_dict(self) -> dict[str, Any]:
        return {**self.net.state_dict(), "buffer": self.buffer.state_dict(), "updates": self.updates}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.net.load_state_dict(s)
        self.buffer.load_state_dict(s["buffer"])
        self.updates = int(s["updates"])
