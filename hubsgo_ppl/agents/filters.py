"""Sub-goal filters: what distinguishes HUBS-GO from h-DQN in the one HRL loop.

- :class:`CriticFilter` (HUBS-GO): Ĝt is the most probable configuration among the critic's current MH
  samples (Sec. 3.4), optionally among those agreeing with the sub-goals already achieved, and each
  high-level minibatch drives one critic update (Algorithm 1, lines 9-11). It also keeps the achieved
  sets of the last ``outcome_window`` successful episodes: the evidence of outcome likelihoods, and
  the safeguard below.
- :class:`NoFilter` (h-DQN): the high level always chooses from G0.

The safeguard. A critic can learn nonsense (a TD likelihood whose evidence is flat, a prior that
outweighs it) and drop from Ĝt a sub-goal every success needs, such as the goal itself; a high level
restricted to that Ĝt can then no longer succeed, and gathers no evidence to correct it. So Ĝt always
contains every sub-goal that was achieved in every one of the recent successful episodes (with
``keep_fraction`` below 1: in at least that share of them): what the agent's own successes show to be
needed is never filtered out. With 1 the guard is the intersection of the recent successes, so a
sub-goal that successes only passed on the way (a cell crossed while wandering) leaves the guard as soon
as one success misses it, and the critic alone decides about it; with 0.5 the many cells an early,
wandering success crosses stayed in Ĝt for dozens of episodes on mazes with many candidates
(docs/results.md). Sub-goals the critic adds are kept too (the guard only adds), and before the first
success the guard is empty. The loop's other guard is ``filter_end`` < 1: the high level still chooses
from G0 in a share of its decisions.
"""

from __future__ import annotations

import math
from collections import deque
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

    def end_episode(self, visited: np.ndarray, success: bool) -> None:
        """An episode ended; ``visited`` (N,) bool: the sub-goals it achieved, at any step of it (those
        its env marks lasting, ``subgoal_lasting``: where they hold at its end)."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


class NoFilter:
    """h-DQN: no critic; Ĝt = G0."""

    name = "none"

    def allowed(self, achieved: np.ndarray | None = None) -> None:
        return None

    def update(self, batch: HighLevelBatch) -> dict[str, float]:
        return {}

    def end_episode(self, visited: np.ndarray, success: bool) -> None:
        return None

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        if state:
            raise ValueError("NoFilter has no state; this checkpoint was written by another agent")


class CriticFilter:
    """HUBS-GO: the Bayesian sub-goal critic filters G0 to Ĝt (Sec. 3.3-3.4), with the safeguard of the
    module docstring (``keep_fraction``; 0 turns it off)."""

    name = "critic"

    def __init__(self, critic: Any, outcome_window: int = 20, keep_fraction: float = 1.0,
                 before_update: str = "g0", complete_missing: bool = False):
        """The arguments are the loop's ``outcome_window``, ``filter_keep`` and ``filter_before_update``,
        checked where they are declared (:class:`~.settings.LoopConfig`). ``complete_missing``: where no
        sample holds every achieved sub-goal, Ĝt is q's completion of them instead of the unconditional
        mode. A transferred critic sets it (experiments/transfer.py): confident of its source run's
        route before the agent knows the new layout, its mode can name a route the agent can no longer
        take (it holds the other route's key)."""
        self.critic = critic
        self.complete_missing = bool(complete_missing)
        self.before_update = before_update
        self.keep_fraction = float(keep_fraction)
        self._mask: np.ndarray | None = None   # None until the first update: Ĝt = G0
        self._outcomes: deque[np.ndarray] = deque(maxlen=int(outcome_window))
        self._outcome_tensor = torch.zeros(0, critic.n)   # the window as the critic reads it (E, N)
        self._keep = np.zeros(critic.n, dtype=bool)
        self._needs_outcomes = critic.likelihood.evidence == "outcomes"

    def allowed(self, achieved: np.ndarray | None = None) -> np.ndarray | None:
        """The mode of the last update's samples; given ``achieved``, the mode of those samples that
        include every achieved sub-goal (``SubgoalCritic.filtered_set``), so that a route the agent
        has committed to (it holds the blue key) is the one Ĝt names. Either way joined with the
        safeguard's sub-goals. Before the critic's first update: G0 (None), or with ``before_update``
        "completion" q's completion of the achieved sub-goals (``SubgoalCritic.completion``): q starts
        at the prior, so the human's edges then steer the high level from the first episode (holding a
        key, Ĝt is its door and the goal; holding nothing, the completion is empty and the high level
        reads G0)."""
        if self._mask is None:
            if self.before_update == "g0":
                return None
            given = np.zeros(self.critic.n, dtype=bool) if achieved is None else np.asarray(achieved, dtype=bool)
            return self.critic.completion(torch.as_tensor(given)).cpu().numpy().astype(bool) | self._keep
        if achieved is None:
            return self._mask | self._keep
        given = torch.as_tensor(np.asarray(achieved, dtype=bool))
        mask = self.critic.filtered_set(given=given, complete_missing=self.complete_missing)
        return mask.cpu().numpy().astype(bool) | self._keep

    def end_episode(self, visited: np.ndarray, success: bool) -> None:
        if not success:
            return
        self._outcomes.append(np.asarray(visited, dtype=bool).copy())
        self._window_changed()

    def _window_changed(self) -> None:
        """Rebuild what depends on the window (once per successful episode, not per update)."""
        if not self._outcomes:
            self._outcome_tensor = torch.zeros(0, self.critic.n)
            self._keep = np.zeros(self.critic.n, dtype=bool)
            return
        window = np.stack(self._outcomes)
        self._outcome_tensor = torch.as_tensor(window, dtype=torch.float32)
        self._keep = (window.mean(axis=0) >= self.keep_fraction if self.keep_fraction > 0
                      else np.zeros(self.critic.n, dtype=bool))

    def outcomes(self) -> torch.Tensor:
        """The achieved sets of the recent successful episodes, (E, N) float, oldest first."""
        return self._outcome_tensor

    def update(self, batch: HighLevelBatch) -> dict[str, float]:
        """One critic update on the minibatch. The TDBatch itself goes to the critic, not its
        ``residuals`` method, so that its ``weight`` scales the TD likelihood: a pool of K minibatches
        counts as their mean. An outcome likelihood gets the
        recent successes attached, which count once whatever the pool; before the first success it has
        no evidence, and no update runs (Ĝt = G0)."""
        if self._needs_outcomes:
            if not self._outcomes:
                return {}
            batch.outcomes = self.outcomes()
        diag = self.critic.update(batch)
        loss = diag.get("loss", float("nan"))
        if not math.isfinite(loss):
            raise FloatingPointError(
                f"critic loss is {loss}: the TD residuals or the likelihood scale overflowed; "
                "lower the high-level learning rate or raise likelihood.scale in the model spec")
        self._mask = self.critic.filtered_set().cpu().numpy().astype(bool)
        out = {f"critic/{k}": float(v) for k, v in diag.items() if isinstance(v, (int, float))}
        out["critic/set_size"] = float(self._mask.sum())
        out["critic/kept"] = float((self._keep & ~self._mask).sum())    # sub-goals only the safeguard adds
        return out

    def marginals(self) -> np.ndarray:
        return self.critic.marginals().detach().cpu().numpy()

    def state_dict(self) -> dict[str, Any]:
        return {"critic": self.critic.state_dict(),
                "mask": None if self._mask is None else torch.as_tensor(self._mask),
                "outcomes": self.outcomes().clone(), "complete_missing": self.complete_missing}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        self.critic.load_state_dict(state["critic"])
        self._mask = None if state["mask"] is None else state["mask"].numpy().astype(bool)
        self.complete_missing = bool(state.get("complete_missing", False))
        self._outcomes.clear()
        for row in state.get("outcomes", torch.zeros(0, self.critic.n)):
            self._outcomes.append(row.numpy().astype(bool))
        self._window_changed()
