"""What every trainer does around an episode: reset with the episode's seed, add up the return, the
length and success, average the update diagnostics, and report an :class:`EpisodeStats`.

The HRL loop (:mod:`~hubsgo_ppl.agents.loop`), HIRO (:mod:`~hubsgo_ppl.agents.hiro`) and the flat
baselines (:mod:`~hubsgo_ppl.agents.flat`) differ in what happens between two env steps; this module
is the part they share.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Iterable, Mapping

import gymnasium as gym

from .seeding import episode_seed

__all__ = ["EpisodeStats", "EpisodeTally", "env_seed", "reset_episode", "sequential_mean"]


@dataclass
class EpisodeStats:
    episode: int
    env_steps: int                  # cumulative, after this episode
    ret: float
    length: int
    success: bool
    options: int
    explore_eps: float
    filter_eps: float
    chosen: list[str] = field(default_factory=list)
    # per option of an HRL episode: the sub-goals achieved where it started ("from"), its sub-goal
    # ("goal"), its env steps ("steps") and whether it reached its sub-goal ("reached")
    option_log: list[dict[str, Any]] = field(default_factory=list)
    scalars: dict[str, float] = field(default_factory=dict)   # means of update diagnostics

    def row(self) -> dict[str, Any]:
        d = asdict(self)
        d.pop("chosen")
        d.pop("option_log")
        d.pop("scalars")
        d["return"] = d.pop("ret")
        d["success"] = int(self.success)
        d.update(self.scalars)
        return d


def env_seed(run_seed: int, episode: int, seed: int | None = None) -> int:
    """The env seed of episode ``episode`` of the run seeded ``run_seed``: ``episode_seed(run_seed,
    episode)``, or ``seed`` when one is given (evaluation)."""
    return episode_seed(run_seed, episode) if seed is None else int(seed)


def reset_episode(env: gym.Env, run_seed: int, episode: int, seed: int | None = None,
                  options: dict | None = None) -> tuple[Any, dict]:
    """Reset ``env`` for episode ``episode`` of the run seeded ``run_seed`` with :func:`env_seed`."""
    extra = {} if options is None else {"options": options}
    return env.reset(seed=env_seed(run_seed, episode, seed), **extra)


def sequential_mean(values: list[float]) -> float:
    """The mean of ``values`` summed left to right (the HRL loop's running sums)."""
    total = 0.0
    for v in values:
        total += v
    return total / len(values)


class EpisodeTally:
    """Return, length and success of one episode, and its diagnostics (means per key).

    ``mean`` reduces one key's values: :func:`sequential_mean` (the default) or e.g. ``np.mean``
    (pairwise summation; HIRO's). The two can differ in the last bits, so each trainer keeps its own.
    """

    def __init__(self, episode: int, mean: Callable[[list[float]], float] = sequential_mean):
        self.episode = episode
        self.ret = 0.0
        self.length = 0
        self.success = False
        self._mean = mean
        self._values: dict[str, list[float]] = {}

    def note(self, info: Mapping[str, Any]) -> None:
        """Success is reported by any step's (or, where a trainer counts it, the reset's) ``is_success``."""
        self.success = self.success or bool(info.get("is_success", False))

    def step(self, reward: float, info: Mapping[str, Any]) -> None:
        """One env step: its reward and its info."""
        self.ret += float(reward)
        self.length += 1
        self.note(info)

    def record(self, scalars: Mapping[str, float] | None) -> None:
        """Diagnostics of one update (None: no update ran)."""
        for k, v in (scalars or {}).items():
            self._values.setdefault(k, []).append(v)

    def put(self, key: str, value: float) -> None:
        """A diagnostic with one value for the whole episode."""
        self._values[key] = [value]

    def means(self) -> dict[str, float]:
        return {k: float(self._mean(v)) for k, v in self._values.items()}

    def stats(self, env_steps: int, options: int, explore_eps: float, filter_eps: float,
              chosen: Iterable[str] = (), option_log: Iterable[dict[str, Any]] = ()) -> EpisodeStats:
        return EpisodeStats(episode=self.episode, env_steps=env_steps, ret=self.ret, length=self.length,
                            success=self.success, options=options, explore_eps=explore_eps,
                            filter_eps=filter_eps, chosen=list(chosen), option_log=list(option_log),
                            scalars=self.means())

