"""The high level's TD minibatch, as the critic scores it (Eq. 2), and the evidence that travels with it.

Light on purpose (torch and numpy only): agents build and pool batches without importing Pyro.
:func:`td_residuals` moves Pyro's provenance tag from the masks to the residuals when the critic's
model calls it (the import happens there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import torch

__all__ = ["NonFiniteError", "TDBatch", "td_residuals"]


_NOT_TD = ("available", "weight", "outcomes", "settled")


class NonFiniteError(FloatingPointError, ValueError):
    """A batch holds NaN or inf: the networks that made it have diverged (a ValueError too, as bad input)."""


@dataclass
class TDBatch:
    """One minibatch of B high-level transitions, for the set-conditioned TD target of Eq. 2.

    ``q_taken``: Q(s_t, g_t) (B,); ``q_next``: Q(s_{t+k}, g') for every candidate g' (B, N);
    ``reward``: the high-level reward (B,); ``discount``: gamma^k * (1 - done) (B,);
    ``available`` (optional, bool (B, N)): the sub-goals selectable at s_{t+k} (e.g. not yet achieved);
    the max of Eq. 2 runs over G(w) ∩ available. Tensors are detached on construction: the critic never
    trains Q.
    ``weight`` scales the batch's TD log-likelihood (Eq. 4) in the ELBO: :meth:`cat` pools K minibatches
    into one update at weight 1/K, so the posterior an update aims at stays that of one minibatch. It
    does not scale ``outcomes``: they are the whole window of recent successes, not a minibatch, and
    count once in every update.
    """

    q_taken: torch.Tensor
    q_next: torch.Tensor
    reward: torch.Tensor
    discount: torch.Tensor
    available: torch.Tensor | None = None
    weight: float = 1.0
    # the achieved sets of recent successful episodes, (E, N) float 0/1: the evidence of likelihoods
    # with ``evidence = "outcomes"`` (CriticFilter attaches them; TD likelihoods ignore them)
    outcomes: torch.Tensor | None = None
    # read the outcomes as those of a settled agent (SubgoalCritic.settled, the critic G* is read from once
    # the loop's settle_at is reached): an outcome likelihood then weighs its evidence by its settled_scale()
    settled: bool = False

    @classmethod
    def cat(cls, batches: "list[TDBatch]", reduce: str = "mean") -> "TDBatch":
        """Pool K minibatches into one batch whose likelihood counts as their ``"mean"`` (weight / K)
        or their ``"sum"`` (every transition at its own weight)."""
        if not batches:
            raise ValueError("TDBatch.cat needs at least one batch")
        if reduce not in ("mean", "sum"):
            raise ValueError(f"TDBatch.cat: reduce must be 'mean' or 'sum', got {reduce!r}")
        if len(batches) == 1:  # K = 1: the mean and the sum are the batch itself
            return batches[0]
        masks = [b.available for b in batches]
        if any(m is None for m in masks) and not all(m is None for m in masks):
            raise ValueError("TDBatch.cat: either every batch has an `available` mask or none has")
        return cls(
            q_taken=torch.cat([b.q_taken for b in batches]),
            q_next=torch.cat([b.q_next for b in batches]),
            reward=torch.cat([b.reward for b in batches]),
            discount=torch.cat([b.discount for b in batches]),
            available=None if masks[0] is None else torch.cat(masks),
            outcomes=batches[-1].outcomes,
            settled=batches[-1].settled,
            weight=sum(b.weight for b in batches) / len(batches) ** (2 if reduce == "mean" else 1),
        )

    def __post_init__(self):
        self.weight = float(self.weight)
        if not (math.isfinite(self.weight) and self.weight > 0):
            raise ValueError(f"TDBatch.weight must be a positive number, got {self.weight!r}")
        if self.available is not None:
            self.available = torch.as_tensor(self.available).detach().bool()
        if self.outcomes is not None:
            self.outcomes = torch.as_tensor(self.outcomes).detach().to(torch.float32)
        self.settled = bool(self.settled)
        for f in fields(self):
            if f.name in _NOT_TD:
                continue
            v = getattr(self, f.name)
            if not isinstance(v, torch.Tensor):
                v = torch.as_tensor(v, dtype=torch.float32)
            setattr(self, f.name, v.detach().to(torch.float32))
        if self.q_next.dim() != 2:
            raise ValueError(f"TDBatch.q_next must have shape (B, N), got {tuple(self.q_next.shape)}")
        b = self.q_next.shape[0]
        for name in ("q_taken", "reward", "discount"):
            if getattr(self, name).shape != (b,):
                raise ValueError(f"TDBatch.{name} must have shape ({b},) to match q_next (B={b}), got {tuple(getattr(self, name).shape)}")
        if self.available is not None and self.available.shape != self.q_next.shape:
            raise ValueError(f"TDBatch.available must have q_next's shape {tuple(self.q_next.shape)}, "
                             f"got {tuple(self.available.shape)}")
        if self.outcomes is not None and (self.outcomes.dim() != 2 or self.outcomes.shape[1] != self.q_next.shape[1]):
            raise ValueError(f"TDBatch.outcomes must have shape (E, {self.q_next.shape[1]}), got {tuple(self.outcomes.shape)}")
        if self.outcomes is not None and not bool(((self.outcomes == 0) | (self.outcomes == 1)).all()):
            raise ValueError("TDBatch.outcomes must hold 0 or 1 (a sub-goal achieved or not in a successful "
                             "episode), and it holds other values (NaN, inf or fractions); pass the achieved sets")
        for f in fields(self):
            if f.name in _NOT_TD:
                continue
            if not bool(torch.isfinite(getattr(self, f.name)).all()):
                raise NonFiniteError(f"TDBatch.{f.name} has NaN or inf entries; check the Q-network outputs/rewards")

    @property
    def n(self) -> int:
        return self.q_next.shape[1]

    def residuals(self, w: torch.Tensor) -> torch.Tensor:
        """y_G(w) - Q(s, g) for each mask in ``w`` (..., N) -> (..., B) (Eq. 2).

        y_G = r + discount * max_{g' in G(w)} Q(s', g'); an empty set bootstraps 0. Pure torch
        masking, so the dependence on w stays visible to TraceGraph_ELBO.
        """
        if w.shape[-1] != self.n:
            raise ValueError(f"masks have {w.shape[-1]} sub-goals but q_next has {self.n} columns")
        return td_residuals(w, *self.tensors())

    def tensors(self) -> tuple[torch.Tensor, ...]:
        """``(q_taken, q_next, reward, discount[, available])``: the arguments of :func:`td_residuals`."""
        out = (self.q_taken, self.q_next, self.reward, self.discount)
        return out if self.available is None else out + (self.available,)


def td_residuals(w, q_taken, q_next, reward, discount, available=None) -> torch.Tensor:
    """:meth:`TDBatch.residuals` on the batch's tensors (the compiled update passes them as inputs)."""
    from ..distributions._provenance import retrack, untrack

    # Provenance is moved from w to the result in one step (same dependency, far fewer tagged ops).
    w, prov = untrack(w)
    selected = w.unsqueeze(-2) > 0.5  # (..., 1, N)
    if available is not None:
        selected = selected & available  # (..., B, N)
    best = torch.where(selected, q_next, -math.inf).amax(-1)  # (..., B)
    bootstrap = torch.where(selected.any(-1), best, 0.0)
    return retrack(reward + discount * bootstrap - q_taken, prov)
