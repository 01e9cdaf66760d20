"""The one HRL loop (Algorithm 1), shared by every hierarchical agent (HUBS-GO, h-DQN).

Each high-level iteration:

1. the filter offers Ĝt (with ``filter_given_achieved``, given the sub-goals achieved so far); with
   probability ε_filter (rising over training, Sec. 3.4) the high level chooses from Ĝt, otherwise
   from G0 — in both cases only among sub-goals not yet achieved, and when reading Ĝt, with learned
   initiation sets (``initiation_tries``), not among those options have failed to reach from here;
2. the high level picks g = argmax Q(s, g') over that set (ε-greedy while training);
3. the low level acts until g is achieved, the env ends, or ``option_steps`` pass (lines 3-8);
4. the transition (s, g, R, s', γ^k) goes to the high-level replay; the high level takes a TD step with
   targets over Ĝt (Eq. 2), and the same minibatch drives the filter's update (lines 9-11), pooled
   with the previous ones every ``critic_every`` minibatches (``TDBatch.cat``; the pool's TD likelihood
   counts as the minibatches' mean, weight 1/K, or with ``critic_pool_weight="sum"`` their sum; an
   outcome likelihood's window of recent successes counts once either way).

The loop is the only place where an environment and the critic meet. It does no IO: it returns
per-episode statistics and leaves logging, progress bars and checkpoints to ``experiments.run``.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from ..infer.readout import FALLBACK
from ..infer.tdbatch import TDBatch
from .episode import EpisodeStats, EpisodeTally, env_seed, reset_episode
from .filters import CriticFilter
from .high_level import HighLevelDQN
from .initiation import InitiationSets
from .low_level import GoalDQN
from .protocols import LowLevel, SubgoalFilter
from .schedules import LinearSchedule
from .seeding import EVAL_LOW_LEVEL_STREAM, LOOP_STREAM, episode_seed, stream_rng

__all__ = ["LoopConfig", "EpisodeStats", "HRLLoop", "episode_seed", "EXPLORE_BY_SUCCESS"]

#: which ε's the recent success rate caps (``LoopConfig.explore_by_success``)
EXPLORE_BY_SUCCESS = ("none", "high", "both")
#: what that rate is taken over (``LoopConfig.success_rate_over``)
SUCCESS_RATE_OVER = ("window", "played")
#: how the learned low level weighs the sub-goals in its TD loss (``LoopConfig.low_goal_weight``)
LOW_GOAL_WEIGHT = ("uniform", "marginal", "prior_marginal")


@dataclass
class LoopConfig:
    total_steps: int = 100_000
    option_steps: int = 40                      # N: low-level steps per high-level decision
    gamma: float = 0.99                         # per primitive step (the high level discounts by γ^k)
    explore_start: float = 1.0                  # high-level ε-greedy exploration (decays)
    explore_end: float = 0.05
    explore_fraction: float = 0.3
    low_explore_start: float = 1.0              # low-level ε-greedy exploration (decays)
    low_explore_end: float = 0.05
    low_explore_fraction: float = 0.3
    filter_start: float = 0.0                   # Sec. 3.4: probability of choosing from Ĝt (rises)
    # below 1, so that a share of the high level's decisions always reads G0: one of the two guards
    # against a critic that learns nonsense (the other is filter_keep; agents/filters.py)
    filter_end: float = 0.9
    filter_fraction: float = 0.5
    # the filter keeps the achieved sets of the last outcome_window successful episodes (the evidence
    # of outcome likelihoods); Ĝt always holds the sub-goals achieved in at least filter_keep of them
    # (1: in every one of them)
    outcome_window: int = 20
    filter_keep: float = 1.0
    # Ĝt before the critic's first update: "g0" (no filter) or "completion" (q's completion of the
    # achieved sub-goals, q being the prior then; agents/filters.py, BEFORE_UPDATE)
    filter_before_update: str = "g0"
    # Ĝt given the achieved sub-goals where no critic sample holds them all: "mode" (the unconditional
    # mode), "completion" (q's completion of them) or "conditional" (the mode of q given them;
    # infer/readout.py, FALLBACK)
    filter_fallback: str = "mode"
    eval_filter: float = 1.0                    # greedy evaluation chooses from Ĝt with this probability
    # h-DQN's per-goal annealing (Kulkarni et al. 2016): the low level's ε for goal g is at least
    # min(low_explore_cap, 1 - its recent success rate on g), so goals it cannot reach yet keep being
    # explored after the schedule has decayed (the cap keeps a failing goal from locking ε at 1).
    # Off by default: on KeyDoor it lowered the mean training return (docs/results.md)
    low_explore_adaptive: bool = False
    low_explore_cap: float = 0.5
    success_rate_alpha: float = 0.05            # rate of the per-goal success-rate moving average
    # "first_reward": the three ε schedules wait at their start values until the first extrinsic
    # reward, then run over the rest of the budget (with no reward seen there is nothing to exploit,
    # and decaying exploration only makes a late first success less likely)
    schedule_from: str = "start"
    # ε capped by recent success: "none", "high" (the high level's ε) or "both" (and the low level's)
    # is at most max(its end value, 1 - the success rate of the last outcome_window training
    # episodes), so exploration falls as soon as episodes succeed, not only as the budget passes
    explore_by_success: str = "none"
    # that rate: "window", the successes of the last outcome_window episodes over outcome_window (the
    # episodes not yet played count as failures); "played", successes / (episodes + 1) over the
    # episodes the window holds (one more failure presumed), so nothing is capped before the first
    # success, a first success lowers ε at once, and failures after it raise ε again
    success_rate_over: str = "window"
    # "uniform": the learned low level's TD loss weighs every sub-goal alike (h-DQN's all-goal
    # relabelling); "marginal" (the MiniGrid default; acts with a critic and the learned grid low
    # level, and is "uniform" without them): after each critic update from evidence (an outcome
    # critic: from the first success on) a sub-goal weighs its marginal P(w_g = 1), at least
    # 1 - filter_end (the share of choices that still read G0), so the low level's capacity goes to
    # the sub-goals the critic has learned to believe in; "prior_marginal": the same, and before that
    # the prior's marginals, read once at the critic's first update call
    low_goal_weight: str = "uniform"
    critic_every: int = 1                       # high-level updates pooled into one critic update
    # how a pool of K minibatches weighs in the TD likelihood (Eq. 4): "mean" (weight 1/K: an update aims
    # at the posterior of one minibatch) or "sum" (weight 1: of all K x B transitions). Equal for K = 1;
    # no effect on an outcome likelihood, whose window of recent successes counts once
    critic_pool_weight: str = "mean"
    filter_refresh: str = "option"              # when the loop reads Ĝt: every "option" or once per "episode"
    # Ĝt given the evidence: the mode of the critic's samples among those that include every sub-goal
    # achieved at the time (CriticFilter.allowed), both for choosing (re-read whenever the achieved set
    # changes) and for each TD target's s'. Holding the blue key, Ĝt is then the blue route, not a
    # yellow route the agent can no longer take (there is no drop action). False (the default, and
    # the arm tasks'): the paper's unconditional mode. The maze preset turns it on.
    filter_given_achieved: bool = False
    # While training, a low-level step in a state where the greedy low level already acted under the
    # same sub-goal in this episode is taken at random: back there, the greedy policy would repeat a
    # path that did not reach the sub-goal, and in a deterministic env a greedy cycle never ends by
    # itself (this caused every late KeyDoor timeout, docs/results.md). States reached after a
    # random step are not marked, so one ε-step does not start a random walk. Discrete action spaces
    # with a learned low level only.
    low_break_cycles: bool = True
    # Greedy evaluation breaks the low level's cycles by the same rule (with low_break_cycles): the
    # agent is evaluated as it acts, minus exploration; every other evaluation step is greedy. False
    # evaluates the bare greedy policy, which loops for the rest of an episode once it enters a cycle
    # (``hubsgo evaluate --no-break-cycles``).
    eval_break_cycles: bool = True
    # Learned initiation sets (agents/initiation.py): 0 is off. K > 0: whenever the loop reads Ĝt
    # (with probability ε_filter) it also leaves out each sub-goal g that K options started from the
    # current achieved set never reached, once an option reached it from a set holding more (a door
    # without its key, a goal behind a closed door). The counts go with the high level in a transfer
    # and a revision
    initiation_tries: int = 0
    # True: the high level never chooses, and its TD targets never bootstrap from, a sub-goal that the
    # env's subgoal_possible() says can no longer hold in this episode (another key, where nothing can
    # be dropped, and the door it would open); envs without it offer every sub-goal not yet achieved
    exclude_impossible: bool = False
    # The agent settles at the end of the first episode at which its success rate over its last
    # outcome_window training episodes (a full window) reaches settle_at (0.9: the episode of "steps to
    # 90% success" in docs/results.md). From then on G*, the set the run reports (subgoals.json, the
    # review), is read from the critic refitted for settle_updates updates on the recent successes at
    # the likelihood's settled power (infer/likelihoods.py, "outcome"; g_star_critic), so it follows
    # what the reliable successes achieve. Training, and Ĝt, keep the critic that reads them at the
    # learning power: runs are the same with or without settling. None: never settles
    settle_at: float | None = 0.9
    settle_updates: int = 300

    def __post_init__(self):
        if self.filter_refresh not in ("option", "episode"):
            raise ValueError(f"loop.filter_refresh must be 'option' or 'episode', got {self.filter_refresh!r}")
        if self.schedule_from not in ("start", "first_reward"):
            raise ValueError(f"loop.schedule_from must be 'start' or 'first_reward', got {self.schedule_from!r}")
        if self.explore_by_success not in EXPLORE_BY_SUCCESS:
            raise ValueError(f"loop.explore_by_success must be one of {', '.join(EXPLORE_BY_SUCCESS)}, "
                             f"got {self.explore_by_success!r}")
        if self.success_rate_over not in SUCCESS_RATE_OVER:
            raise ValueError(f"loop.success_rate_over must be one of {', '.join(SUCCESS_RATE_OVER)}, "
                             f"got {self.success_rate_over!r}")
        if self.low_goal_weight not in LOW_GOAL_WEIGHT:
            raise ValueError(f"loop.low_goal_weight must be one of {', '.join(LOW_GOAL_WEIGHT)}, "
                             f"got {self.low_goal_weight!r}")
        if self.filter_fallback not in FALLBACK:
            raise ValueError(f"loop.filter_fallback must be one of {', '.join(FALLBACK)}, got {self.filter_fallback!r}")
        if self.critic_pool_weight not in ("mean", "sum"):
            raise ValueError(f"loop.critic_pool_weight must be 'mean' or 'sum', got {self.critic_pool_weight!r}")
        if not 0.0 <= self.filter_end <= 1.0 or not 0.0 <= self.filter_start <= 1.0:
            raise ValueError(f"loop.filter_start and loop.filter_end must be in [0, 1], got {self.filter_start!r}, {self.filter_end!r}")
        if int(self.critic_every) < 1:
            raise ValueError(f"loop.critic_every must be a positive integer, got {self.critic_every!r}")
        if int(self.outcome_window) < 1:
            raise ValueError(f"loop.outcome_window must be a positive integer, got {self.outcome_window!r}")
        if self.settle_at is not None and not 0.0 < float(self.settle_at) <= 1.0:
            raise ValueError(f"loop.settle_at must be in (0, 1], or null (never settles), got {self.settle_at!r}")
        if int(self.settle_updates) < 1:
            raise ValueError(f"loop.settle_updates must be a positive integer, got {self.settle_updates!r}")
        if int(self.initiation_tries) < 0:
            raise ValueError(f"loop.initiation_tries must be 0 (off) or a positive integer, got {self.initiation_tries!r}")


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
        self.env_steps = 0
        self.episodes = 0
        self._explore = LinearSchedule(config.explore_start, config.explore_end, config.explore_fraction)
        self._low_explore = LinearSchedule(config.low_explore_start, config.low_explore_end,
                                           config.low_explore_fraction)
        self._filter = LinearSchedule(config.filter_start, config.filter_end, config.filter_fraction)
        self.first_reward_step: int | None = None       # env step of the first extrinsic reward
        self.success_rate = np.zeros(len(self.names))   # per-goal moving average of option success
        self._recent: deque[bool] = deque(maxlen=config.outcome_window)  # success of recent training episodes
        self._pending: list = []                # high-level minibatches waiting for the next critic update
        self.settled_step: int | None = None    # env step at which the agent settled (settle_at)
        self._g_star: tuple[tuple[int, int], Any] | None = None     # (when, critic) of g_star_critic
        self.initiation = (InitiationSets(self.names, config.initiation_tries)
                           if int(config.initiation_tries) > 0 else None)
        # the weights need a critic to read and a low level that takes them (GoalDQN); without either
        # (h-DQN, a scripted or continuous low level) every sub-goal weighs alike, as with "uniform"
        self._weighs_low = (config.low_goal_weight != "uniform" and isinstance(low, GoalDQN)
                            and isinstance(subgoal_filter, CriticFilter))
        self._possible = (getattr(env.unwrapped, "subgoal_possible", None)
                          if config.exclude_impossible else None)
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

    def schedule_progress(self) -> float:
        """Where the ε schedules are: ``progress()``, or with ``schedule_from="first_reward"`` the
        fraction of the budget left at the first extrinsic reward that has passed since (0 before it)."""
        if self.cfg.schedule_from == "start":
            return self.progress()
        if self.first_reward_step is None:
            return 0.0
        left = max(self.cfg.total_steps - self.first_reward_step, 1)
        return (self.env_steps - self.first_reward_step) / left

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

    def _open(self, achieved: np.ndarray) -> np.ndarray:
        """The sub-goals the high level may choose from now: those not yet achieved (and, with
        ``exclude_impossible``, still possible); every one where none is left."""
        base = ~achieved
        if self._possible is not None:
            possible = base & self._possible()
            base = possible if possible.any() else base
        return base if base.any() else np.ones_like(achieved)

    def _allowed(self, achieved: np.ndarray, filter_eps: float) -> np.ndarray:
        base = self._open(achieved)
        if (self.cfg.filter_refresh == "option" or self._ghat_given is None
                or (self.cfg.filter_given_achieved and not np.array_equal(achieved, self._ghat_given))):
            self._read_filter(achieved)
        ghat = self._ghat
        if (ghat is not None or self.initiation is not None) and self.rng.random() < filter_eps:
            open_ = base if self.initiation is None else base & ~self.initiation.blocked(achieved)
            restricted = open_ & ghat if ghat is not None else open_
            for choice in (restricted, open_):
                if choice.any():
                    return choice
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
        explore, low_explore, filter_eps = 0.0, 0.0, cfg.eval_filter     # greedy evaluation
        done = False
        while not done:
            if train:
                p = self.schedule_progress()
                explore, low_explore, filter_eps = self._explore(p), self._low_explore(p), self._filter(p)
                explore, low_explore = self._cap_by_success(explore, low_explore)
            allowed = self._allowed(achieved, filter_eps)
            g = self.high.select(obs, allowed, explore)
            started_at = achieved
            self.low.begin_option()
            s0, R, k = obs, 0.0, 0
            terminated = truncated = False
            goal_explore = low_explore
            if train and cfg.low_explore_adaptive:
                goal_explore = max(low_explore, min(cfg.low_explore_cap, 1.0 - float(self.success_rate[g])))
            while k < cfg.option_steps:
                step_explore, key = goal_explore, None
                if breaking:
                    key = (g, np.asarray(obs).tobytes())
                    if key in greedy_at:
                        step_explore, revisits = 1.0, revisits + 1
                action = self.low.act(obs, g, step_explore, env)
                if key is not None and not self.low.explored:
                    greedy_at.add(key)
                next_obs, reward, terminated, truncated, info = env.step(action)
                next_achieved = np.asarray(info["subgoals"], dtype=bool)
                if train and self.low.learns:
                    tally.record(self.low.observe(obs, action, next_obs, achieved, next_achieved, terminated))
                R += (cfg.gamma ** k) * float(reward)
                tally.step(reward, info)
                k += 1
                if train:
                    self.env_steps += 1
                    if reward > 0 and self.first_reward_step is None:
                        self.first_reward_step = self.env_steps
                obs, achieved = next_obs, next_achieved
                visited |= achieved
                if terminated or truncated or achieved[g]:
                    break
            option_log.append({"from": [n for n, a in zip(self.names, started_at) if a], "goal": self.names[g],
                               "steps": k, "reached": bool(achieved[g])})
            if train:
                a = cfg.success_rate_alpha
                self.success_rate[g] = (1 - a) * self.success_rate[g] + a * float(achieved[g])
                if self.initiation is not None:
                    self.initiation.record(started_at, g, bool(achieved[g]))
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
                        pooled, self._pending = TDBatch.cat(self._pending, cfg.critic_pool_weight), []
                        learned = self.filter.update(pooled)    # {} where the critic had no evidence
                        tally.record(learned)
                        self._weigh_low_level(bool(learned))
        if train:
            self.filter.end_episode(visited, tally.success)
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
        """``low_goal_weight``: after a critic update from evidence (or, with "prior_marginal", at the
        first update call), the low level weighs sub-goal g by max(P(w_g = 1), 1 - filter_end)."""
        first_call = self.cfg.low_goal_weight == "prior_marginal" and self.low.goal_weight is None
        if self._weighs_low and (learned or first_call):
            weights = np.maximum(self.filter.marginals(), 1.0 - self.cfg.filter_end)
            self.low.goal_weight = torch.as_tensor(weights, dtype=torch.float32)

    def _cap_by_success(self, explore: float, low_explore: float) -> tuple[float, float]:
        """The two ε's under ``explore_by_success``: at most max(end, 1 - recent success rate)."""
        mode = self.cfg.explore_by_success
        if mode == "none":
            return explore, low_explore
        if self.cfg.success_rate_over == "played":
            failing = 1.0 - sum(self._recent) / (len(self._recent) + 1.0)
        else:
            failing = 1.0 - sum(self._recent) / self.cfg.outcome_window     # validated positive
        explore = min(explore, max(self.cfg.explore_end, failing))
        if mode == "both":
            low_explore = min(low_explore, max(self.cfg.low_explore_end, failing))
        return explore, low_explore

    def train_chunk(self) -> list[EpisodeStats]:
        """The trainer protocol used by ``experiments.run``: one training episode per call."""
        return [self.run_episode(train=True)]

    # -- checkpointing -------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        s = {"env_steps": self.env_steps, "episodes": self.episodes,
             "rng": self.rng.bit_generator.state, "high": self.high.state_dict(),
             "high_rng": self.high.rng.bit_generator.state, "filter": self.filter.state_dict(),
             "success_rate": self.success_rate.copy(), "first_reward_step": self.first_reward_step,
             "recent_success": list(self._recent), "settled_step": self.settled_step,
             # minibatches waiting for the next pooled critic update (the pool spans episodes)
             "pending": [{f.name: getattr(b, f.name) for f in fields(b)} for b in self._pending]}
        if self.initiation is not None:
            s["initiation"] = self.initiation.state_dict()
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
        self.first_reward_step = s.get("first_reward_step")
        self._recent.clear()
        self._recent.extend(bool(x) for x in s.get("recent_success", []))
        self.settled_step = s.get("settled_step")
        self._g_star = None
        self._pending = [TDBatch(**b) for b in s.get("pending", [])]
        if "success_rate" in s:
            self.success_rate = np.asarray(s["success_rate"], dtype=float).copy()
        if self.initiation is not None:
            self.initiation.load_state_dict(s.get("initiation", {}))
        if self.low.learns:
            self.low.load_state_dict(s["low"])
            self.low.rng.bit_generator.state = s["low_rng"]
