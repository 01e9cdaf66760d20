"""The contracts between the parts of an agent, as code.

- :class:`Trainer`: what ``experiments.run`` drives (HRL loop, HIRO, the flat SB3 baselines).
- :class:`LowLevel`: what the HRL loop asks of a low level; :class:`LowLevelBase` gives every member a
  default, so the loop calls members and never probes for them.
- :class:`SubgoalFilter`: what the HRL loop asks of a filter; defined in :mod:`.filters` and
  re-exported here.
- :class:`HIROLowLevel`: HIRO's goal-vector low levels (their own contract: the off-policy correction
  needs a log-likelihood).
- :class:`Controller`: a scripted controller wrapped by :class:`~.low_level.ScriptedLowLevel`.
"""

from __future__ import annotations

import abc
from typing import Any, Protocol, runtime_checkable

import gymnasium as gym
import numpy as np
import torch

from .episode import EpisodeStats
from .filters import SubgoalFilter

__all__ = ["Budget", "Trainer", "LowLevel", "LowLevelBase", "SubgoalFilter", "HIROLowLevel", "Controller"]


@runtime_checkable
class Budget(Protocol):
    """A trainer's settings as far as the run harness reads them."""

    total_steps: int        # the env-step budget (a resumed run may raise it)


@runtime_checkable
class Trainer(Protocol):
    """What ``experiments.run`` drives: chunks of training, greedy evaluation episodes, checkpoints."""

    episodes: int           # training episodes finished
    env_steps: int          # training env steps taken
    cfg: Budget

    def train_chunk(self) -> list[EpisodeStats]:
        """Train until at least one episode ends (the one in progress is finished even past the
        budget); the finished episodes, in order."""

    def run_episode(self, train: bool = ..., seed: int | None = None) -> EpisodeStats:
        """One episode. ``train=False`` is greedy evaluation (no exploration, no updates, no counters
        advanced), reset with ``seed``."""

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue exactly (plain data: tensors, arrays, numbers, strings)."""

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


@runtime_checkable
class LowLevel(Protocol):
    """A low level of the HRL loop: acts towards the sub-goal the high level chose."""

    learns: bool            # False: the loop never calls observe() and checkpoints nothing of it
    explored: bool          # whether the last act() was an exploratory (random) action
    rng: np.random.Generator | None     # checkpointed by the loop when the low level learns

    def act(self, obs: np.ndarray, goal: int, explore_eps: float, env: gym.Env) -> Any:
        """The action towards sub-goal ``goal``; ``explore_eps = 0`` is greedy."""

    def begin_option(self) -> None:
        """The high level has chosen a new sub-goal."""

    def observe(self, obs: Any, action: Any, next_obs: Any, before: np.ndarray, after: np.ndarray,
                terminated: bool) -> dict[str, float] | None:
        """One training transition (``before``/``after``: the sub-goal flags); diagnostics to log, or
        None when no update ran."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


class LowLevelBase(abc.ABC):
    """:class:`LowLevel` with defaults: it does not learn, keeps no per-option state, and does not say
    that it acted greedily (``explored = True``, so the loop's cycle breaking never marks its states).
    Subclasses implement :meth:`act`, and a learning one ``learns = True``, ``rng``, :meth:`observe`
    and the state methods."""

    learns: bool = False
    explored: bool = True
    rng: np.random.Generator | None = None

    @abc.abstractmethod
    def act(self, obs: np.ndarray, goal: int, explore_eps: float, env: gym.Env) -> Any: ...

    def begin_option(self) -> None:
        return None

    def observe(self, obs: Any, action: Any, next_obs: Any, before: np.ndarray, after: np.ndarray,
                terminated: bool) -> dict[str, float] | None:
        return None

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        return None


@runtime_checkable
class HIROLowLevel(Protocol):
    """A HIRO low level: goal vectors in, a log-likelihood for the off-policy correction."""

    discrete: bool

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> Any: ...

    def log_lik(self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """``log π(action | obs, goal)`` over leading dims (a surrogate for deterministic policies)."""

    def update(self, batch: dict[str, torch.Tensor], noise: torch.Tensor) -> dict[str, float]:
        """One update on a replay minibatch; ``noise`` is standard normal (drawn by HIRO's generator)."""

    def state_dict(self) -> dict[str, Any]: ...

    def load_state_dict(self, state: dict[str, Any]) -> None: ...


@runtime_checkable
class Controller(Protocol):
    """A scripted controller: an action towards sub-goal ``goal_index`` on the env's current state."""

    def act(self, env: gym.Env, goal_index: int) -> np.ndarray: ...

    def reset(self) -> None:
        """A new option starts."""
