"""The one HRL loop (Algorithm 1), shared by every hierarchical agent (HUBS-GO, h-DQN).

Each high-level iteration:

1. the filter offers Ĝt (with ``filter_given_achieved``, given the sub-goals achieved so far); with
   probability ε_filter (rising over training, Sec. 3.4) the high level chooses from Ĝt, otherwise
   from G0 — in both cases only among sub-goals not yet achieved;
2. the high level picks g = argmax Q(s, g') over that set (ε-greedy while training);
3. the low level acts until g is achieved, the env ends, or ``option_steps`` pass (lines 3-8);
4. the transition (s, g, R, s', γ^k) goes to the high-level replay; the high level takes a TD step with
   targets over Ĝt (Eq. 2), and the same minibatch drives the filter's update (lines 9-11), pooled
   with the previous ones every ``critic_every`` minibatches (``TDBatch.cat``; the pool's TD likelihood
   counts as the minibatches' mean, weight 1/K; an outcome likelihood's window of recent successes
   counts once).

The loop is the only place where an environment and the critic meet. It does no IO: it returns
per-episode statistics and leaves logging, progress bars and checkpoints to ``experiments.run``.
"""

from __future__ import annotations

from collections import deque
from dataclasses import fields
from typing import Any, Generator

import gymnasium as gym
import numpy as np
import torch

from ..infer.tdbatch import TDBatch
from .episode import EpisodeStats, EpisodeTally, env_seed, reset_episode
from .filters import CriticFilter
from .high_level import HighLevelDQN
from .low_level import GoalDQN
from .protocols import LowLevel, SubgoalFilter
from .schedules import LinearSchedule
from .settings import LoopConfig
from .seeding import EVAL_LOW_LEVEL_STREAM, LOOP_STREAM, episode_seed, stream_rng

__all__ = ["LoopConfig", "EpisodeStats", "HRLLoop", "episode_seed", "UPDATE_LOW"]

UPDATE_LOW = "update_low"     # what HRLLoop.episode_steps yields where the low level's gradient step is due


class HRLLoop:
    """Algorithm 1 on the trainer protocol (:class:`~.protocols.Trainer`): one training episode per chunk."""

    def __init__(self, env: gym.Env, high: HighLevelDQN, low: LowLevel, subgoal_filter: SubgoalFilter,
                 config: LoopConfig, seed: int):
        self.env = env
        self.high, self.low, self.filter = high, low, subgoal_filter
        self.cfg = config
        self.seed = seed
        self.rng = stream_rng(seed, LOOP_STREAM)
        self.names: list[str] = list(env.unwrapped.subgoal_names)
        # the sub-goals a success counts only where they hold at its end (an env's optional
        # ``subgoal_lasting``: where an arm task's objects rest); every other one where it held at any step
        lasting = getattr(env.unwrapped, "subgoal_lasting", None)
        self._lasting = (np.asarray(lasting(), dtype=bool) if callable(lasting)
                         else np.zeros(len(self.names), dtype=bool))
        self.env_steps = 0
        self.episodes = 0
        self._explore = LinearSchedule(config.explore_start, config.explore_end, config.explore_fraction)
        self._low_explore = LinearSchedule(config.low_explore_start, config.low_explore_end,
                                           config.low_explore_fraction)
        self._filter = LinearSchedule(config.filter_start, config.filter_end, config.filter_fraction)
        self._recent: deque[bool] = deque(maxlen=config.outcome_window)  # success of recent training episodes
        self._pending: list = []                # high-level minibatches waiting for the next critic update
        self.settled_step: int | None = None    # env step at which the agent settled (settle_at)
        self._g_star: tuple[tuple[int, int], Any] | None = None     # (when, critic) of g_star_critic
        # the weights need a critic to read and a low level that takes them (GoalDQN); without either
        # (h-DQN, a scripted or continuous low level) every sub-goal weighs alike, as with "uniform"
        self._weighs_low = (config.low_goal_weight != "uniform" and isinstance(low, GoalDQN)
                            and isinstance(subgoal_filter, CriticFilter))
        self._ghat: np.ndarray | None = None    # Ĝt as the loop sees it (refreshed per option or per episode)
        self._ghat_given: np.ndarray | None = None   # the achieved set Ĝt was last read with
        self._break_cycles = (config.low_break_cycles and low.learns
                              and isinstance(env.action_space, gym.spaces.Discrete))

    @property
    def eval_breaks_cycles(self) -> bool:
        """Whether greedy evaluation (``run_episode(train=False)``) breaks the low level's cycles."""
        return bool(self._break_cycles and self.cfg.eval_break_cycles)

    # -- one episode ---------------------------------------------------------------------------------
    def progress(self) -> float:
        return self.env_steps / max(self.cfg.total_steps, 1)

    def _read_filter(self, achieved: np.ndarray) -> None:
        given = self.cfg.filter_given_achieved
        self._ghat = self.filter.allowed(achieved if given else None)
        self._ghat_given = achieved.copy()

    def _target_mask(self, achieved_next: torch.Tensor) -> Any:
        """Ĝt for each TD target's s' (the high level's minibatch), given what s' has achieved."""
        if self.cfg.filter_given_achieved:
            mask = self.filter.allowed(achieved_next.numpy())
        else:
            mask = self.filter.allowed()
        return None if mask is None else torch.as_tensor(mask)

    @staticmethod
    def _open(achieved: np.ndarray) -> np.ndarray:
        """The sub-goals the high level may choose from now: those not yet achieved; every one where
        none is left."""
        base = ~achieved
        return base if base.any() else np.ones_like(achieved)

    def _allowed(self, achieved: np.ndarray, filter_eps: float) -> np.ndarray:
        base = self._open(achieved)
        if (self.cfg.filter_refresh == "option" or self._ghat_given is None
                or (self.cfg.filter_given_achieved and not np.array_equal(achieved, self._ghat_given))):
            self._read_filter(achieved)
        ghat = self._ghat
        if ghat is not None and self.rng.random() < filter_eps:
            restricted = base & ghat
            if restricted.any():
                return restricted
        return base

    def run_episode(self, train: bool = True, seed: int | None = None) -> EpisodeStats:
        """Run one episode (Algorithm 1). ``train=False`` is greedy evaluation: no exploration, no updates;
        a learned low level's random steps (the cycle rule) then come from a stream of the episode's own
        seed, and its training stream is left as it was."""
        if train or not self.low.learns:
            return self._episode(train, seed)
        trained = self.low.rng
        self.low.rng = stream_rng(env_seed(self.seed, self.episodes, seed), EVAL_LOW_LEVEL_STREAM)
        try:
            return self._episode(False, seed)
        finally:
            self.low.rng = trained

    def _episode(self, train: bool, seed: int | None) -> EpisodeStats:
        """One episode, the low level's actions and updates served here, one at a time."""
        steps = self.episode_steps(train, seed)
        low = self.low
        request = next(steps)
        try:
            while True:
                if request is UPDATE_LOW:
                    request = steps.send(low.update())
                else:
                    request = steps.send(low.act(request[0], request[1], request[2], self.env))
        except StopIteration as end:
            return end.value

    def episode_steps(self, train: bool, seed: int | None) -> Generator[Any, Any, EpisodeStats]:
        """One episode as a generator: it yields ``(obs, g, explore_eps)`` where the low level must act
        (send the action back) and :data:`UPDATE_LOW` where a learned GoalDQN low level's gradient step
        is due (send its stats back); it returns the episode's statistics. :meth:`run_episode` serves
        the requests one at a time; a lockstep runner (``experiments.lockstep``) serves several seeds'
        requests together."""
        env, cfg = self.env, self.cfg
        obs, info = reset_episode(env, self.seed, self.episodes, seed)
        tally = EpisodeTally(self.episodes)     # the loop counts success from the steps, not the reset
        achieved = np.asarray(info["subgoals"], dtype=bool)
        visited = achieved.copy()                       # achieved at any step of the episode
        option_log: list[dict[str, Any]] = []
        self._read_filter(achieved)     # with filter_refresh="episode", Ĝt holds until the achieved set changes
        greedy_at: set[tuple[int, bytes]] = set()   # (sub-goal, state) where the low level acted greedily
        breaking = self._break_cycles if train else self.eval_breaks_cycles
        revisits = 0
        deferred = isinstance(self.low, GoalDQN)
        explore, low_explore, filter_eps = 0.0, 0.0, 1.0     # greedy evaluation: always from Ĝt
        done = False
        while not done:
            if train:
                p = self.progress()
                explore, low_explore, filter_eps = self._explore(p), self._low_explore(p), self._filter(p)
            allowed = self._allowed(achieved, filter_eps)
            g = self.high.select(obs, allowed, explore)
            started_at = achieved
            self.low.begin_option()
            s0, R, k = obs, 0.0, 0
            terminated = truncated = False
            while k < cfg.option_steps:
                step_explore, key = low_explore, None
                if breaking:
                    key = (g, np.asarray(obs).tobytes())
                    if key in greedy_at:
                        step_explore, revisits = 1.0, revisits + 1
                action = yield (obs, g, step_explore)
                if key is not None and not self.low.explored:
                    greedy_at.add(key)
                next_obs, reward, terminated, truncated, info = env.step(action)
                next_achieved = np.asarray(info["subgoals"], dtype=bool)
                if train and self.low.learns:
                    if deferred:        # GoalDQN: its replay here, its gradient step where the runner serves it
                        if self.low.store(obs, action, next_obs, achieved, next_achieved, terminated):
                            tally.record((yield UPDATE_LOW))
                    else:
                        tally.record(self.low.observe(obs, action, next_obs, achieved, next_achieved, terminated))
                R += (cfg.gamma ** k) * float(reward)
                tally.step(reward, info)
                k += 1
                if train:
                    self.env_steps += 1
                obs, achieved = next_obs, next_achieved
                visited |= achieved
                if terminated or truncated or achieved[g]:
                    break
            option_log.append({"from": [n for n, a in zip(self.names, started_at) if a], "goal": self.names[g],
                               "steps": k, "reached": bool(achieved[g])})
            done = terminated or truncated
            if train:
                available = self._open(achieved)
                discount = 0.0 if terminated else cfg.gamma ** k
                self.high.store(s0, g, R, obs, discount, available)
                if self.high.ready():
                    stats, batch = self.high.update(self._target_mask)
                    tally.record(stats)
                    self._pending.append(batch)
                    if len(self._pending) >= cfg.critic_every:
                        pooled, self._pending = TDBatch.cat(self._pending), []
                        learned = self.filter.update(pooled)    # {} where the critic had no evidence
                        tally.record(learned)
                        self._weigh_low_level(bool(learned))
        if train:
            self.filter.end_episode(np.where(self._lasting, achieved, visited), tally.success)
            self._recent.append(bool(tally.success))
            if (self.settled_step is None and cfg.settle_at is not None
                    and len(self._recent) == cfg.outcome_window
                    and sum(self._recent) >= cfg.settle_at * cfg.outcome_window):
                self.settled_step = self.env_steps
            self.episodes += 1
            if self._break_cycles:
                tally.put("low/revisits", float(revisits))
        return tally.stats(self.env_steps, len(option_log), explore_eps=explore, filter_eps=filter_eps,
                           chosen=[o["goal"] for o in option_log], option_log=option_log)

    def g_star_critic(self) -> Any:
        """The critic that G* is read from: before the agent settles (or without ``settle_at``) the
        filter's own critic; once it has settled, a copy refitted for ``settle_updates`` updates on the
        recent successes at the likelihood's settled power (``SubgoalCritic.settled``). The filter's
        critic, which chooses Ĝt and goes on training, is unchanged. None for an agent without a critic."""
        critic = getattr(self.filter, "critic", None)
        if critic is None or self.settled_step is None:
            return critic
        when = (self.env_steps, int(critic.num_updates))
        if self._g_star is None or self._g_star[0] != when:
            self._g_star = (when, critic.settled(self.filter.outcomes(), int(self.cfg.settle_updates)))
        return self._g_star[1]

    def _weigh_low_level(self, learned: bool) -> None:
        """``low_goal_weight="marginal"``: after a critic update from evidence, the low level weighs
        sub-goal g by max(P(w_g = 1), 1 - filter_end)."""
        if self._weighs_low and learned:
            weights = np.maximum(self.filter.marginals(), 1.0 - self.cfg.filter_end)
            self.low.goal_weight = torch.as_tensor(weights, dtype=torch.float32)

    def train_chunk(self) -> list[EpisodeStats]:
        """The trainer protocol used by ``experiments.run``: one training episode per call."""
        return [self.run_episode(train=True)]

    # -- checkpointing -------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        s = {"env_steps": self.env_steps, "episodes": self.episodes,
             "rng": self.rng.bit_generator.state, "high": self.high.state_dict(),
             "high_rng": self.high.rng.bit_generator.state, "filter": self.filter.state_dict(),
             "recent_success": list(self._recent), "settled_step": self.settled_step,
             # minibatches waiting for the next pooled critic update (the pool spans episodes)
             "pending": [{f.name: getattr(b, f.name) for f in fields(b)} for b in self._pending]}
        if self.low.learns:
            s["low"] = self.low.state_dict()
            s["low_rng"] = self.low.rng.bit_generator.state
        return s

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.env_steps, self.episodes = int(s["env_steps"]), int(s["episodes"])
        self.rng.bit_generator.state = s["rng"]
        self.high.load_state_dict(s["high"])
        self.high.rng.bit_generator.state = s["high_rng"]
        self.filter.load_state_dict(s["filter"])
        self._recent.clear()
        self._recent.extend(bool(x) for x in s.get("recent_success", []))
        self.settled_step = s.get("settled_step")
        self._g_star = None
        self._pending = [TDBatch(**b) for b in s.get("pending", [])]
        if self.low.learns:
            self.low.load_state_dict(s["low"])
            self.low.rng.bit_generator.state = s["low_rng"]
