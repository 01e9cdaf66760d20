"""Sub-goal filters: what distinguishes HUBS-GO from h-DQN in the one HRL loop.

- :class:`CriticFilter` (HUBS-GO): Ĝt is the most probable configuration among the critic's current MH
  samples (Sec. 3.4), optionally among those agreeing with the sub-goals already achieved, and each
  high-level minibatch drives one critic update (Algorithm 1, lines 9-11).
- :class:`NoFilter` (h-DQN): the high level always chooses from G0.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import numpy as np
import torch

from .high_level import HighLevelBatch

__all__ = ["SubgoalFilter", "CriticFilter", "NoFilter"]


class SubgoalFilter(Protocol):
    name: str

    def allowed(self, achieved: np.ndarray | None = None) -> np.ndarray | None:
        """Ĝt as a bool mask over G0, or None when this agent does not filter.

        ``achieved`` ((N,) or (B, N) bool), when given, is the evidence of the sub-goals the agent has
        already achieved; the result then has its shape."""

    def update(self, batch: HighLevelBatch) -> dict[str, float]:
        """Learn from one high-level minibatch; returns scalars to log."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


class NoFilter:
    """h-DQN: no critic; Ĝt = G0."""

    name = "none"

    def allowed(self, achieved: np.ndarray | None = None) -> None:
        return None

    def update(self, batch: HighLevelBatch) -> dict[str, float]:
        return {}

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state:
            raise ValueError("NoFilter has no state; this checkpoint was written by another agent")


class CriticFilter:
    """HUBS-GO: the Bayesian sub-goal critic filters G0 to Ĝt (Sec. 3.3-3.4)."""

    name = "critic"

    def __init__(self, critic: Any):
        self.critic = critic
        self._mask: np.ndarray | None = None   # None until the first update: Ĝt = G0

    def allowed(self, achieved: np.ndarray | None = None) -> np.ndarray | None:
        """The mode of the last update's samples; given ``achieved``, the mode of those samples that
        include every achieved sub-goal (``SubgoalCritic.filtered_set``), so that a route the agent
        has committed to (it holds the blue key) is the one Ĝt names."""
        if self._mask is None or achieved is None:
            return self._mask
        given = torch.as_tensor(np.asarray(achieved, dtype=bool))
        return self.critic.filtered_set(given=given).cpu().numpy().astype(bool)

    def update(self, batch: HighLevelBatch) -> dict[str, float]:
        """One critic update on the minibatch. The TDBatch itself goes to the critic, not its
        ``residuals`` method, so that its ``weight`` scales the likelihood: a pool of K minibatches counts
        as their mean or their sum (``loop.critic_pool_weight``)."""
        diag = self.critic.update(batch)
        loss = diag.get("loss", float("nan"))
        if not math.isfinite(loss):
            raise FloatingPointError(
                f"critic loss is {loss}: the TD residuals or the likelihood scale overflowed; "
                "lower the high-level learning rate or raise likelihood.scale in the model spec")
        self._mask = self.critic.filtered_set().cpu().numpy().astype(bool)
        out = {f"critic/{k}": float(v) for k, v in diag.items() if isinstance(v, (int, float))}
        out["critic/set_size"] = float(self._mask.sum())
        return out

    def marginals(self) -> np.ndarray:
        return self.critic.marginals().detach().cpu().numpy()

    def state_dict(self) -> dict[str, Any]:
        return {"critic": self.critic.state_dict(),
                "mask": None if self._mask is None else torch.as_tensor(self._mask)}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.critic.load_state_dict(state["critic"])
        self._mask = None if state["mask"] is None else state["mask"].numpy().astype(bool)
