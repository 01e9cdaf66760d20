"""Flat baselines from Stable-Baselines3 (paper Sec. 4.2): DQN, DDQN and PPO on the grids, TD3 on the arms.

SB3 does the learning; :class:`SB3Trainer` adapts it to the trainer protocol that ``experiments.run``
drives (``train_chunk``, ``run_episode``, ``state_dict``), so every baseline writes the same run
directory and ``metrics.csv`` as HUBS-GO.

Three things SB3 does not give us, and how this module supplies them:

- **Explicit seeding.** SB3 draws from the process-global ``random``/``np.random``/``torch`` RNGs
  (replay sampling, ε-greedy, action noise, PPO's sampling). Every SB3 call runs inside
  :meth:`SB3Trainer._sandbox`, which swaps in this trainer's own global-RNG states and swaps the
  caller's back afterwards; the states are part of the checkpoint. Training episodes are seeded with
  :func:`~hubsgo_ppl.agents.seeding.episode_seed` by :class:`SeededEpisodes`.
- **Checkpoints of plain data** (SB3's own saves pickle objects such as learning-rate schedules, which
  break across versions and run code on load). We store SB3's
  ``get_parameters()`` (policy and optimiser ``state_dict``s), the filled part of the replay buffer as
  arrays, the counters and the RNG states; never the model object.
- **Exact resume mid-episode.** A chunk ends on an SB3 training boundary (a whole ``train_freq`` unit,
  or a whole PPO rollout), which is usually mid-episode. The checkpoint keeps the actions of the
  unfinished episode; loading replays them from the episode's seed to rebuild the env state, so a
  resumed run continues exactly as an uninterrupted one.

``ddqn`` is SB3's DQN with the double-Q target (van Hasselt et al. 2016): the online network picks
the next action, the target network values it. ``dqn`` is SB3's DQN unchanged.
"""

from __future__ import annotations

import contextlib
import random
from typing import Any, Iterator

import gymnasium as gym
import numpy as np
import torch
import torch.nn.functional as F
from stable_baselines3 import DQN, PPO, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger as SB3Logger
from stable_baselines3.common.noise import NormalActionNoise
from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
from stable_baselines3.common.vec_env import DummyVecEnv

from .episode import EpisodeStats, EpisodeTally, reset_episode
from .seeding import SB3_EVAL_EPISODE, SB3_STREAM, stream_seed

__all__ = ["DoubleDQN", "SeededEpisodes", "SB3Trainer", "SB3Config", "build_dqn", "build_ddqn", "build_ppo",
           "build_td3"]

_REPLAY_FIELDS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class DoubleDQN(DQN):
    """SB3's DQN with the double-Q target ``y = r + γ Q_target(s', argmax_a Q_online(s', a))``."""

    def train(self, gradient_steps: int, batch_size: int = 100) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        losses = []
        for _ in range(gradient_steps):
            batch = self.replay_buffer.sample(batch_size, env=self._vec_normalize_env)
            discounts = batch.discounts if batch.discounts is not None else self.gamma
            with torch.no_grad():
                # decoupling selection (online) from evaluation (target) removes max-operator bias
                next_a = self.q_net(batch.next_observations).argmax(dim=1, keepdim=True)
                next_q = self.q_net_target(batch.next_observations).gather(1, next_a)
                target = batch.rewards + (1 - batch.dones) * discounts * next_q
            q = self.q_net(batch.observations).gather(1, batch.actions.long())
            loss = F.smooth_l1_loss(q, target)
            losses.append(loss.item())
            self.policy.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
            self.policy.optimizer.step()
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")
        self.logger.record("train/loss", float(np.mean(losses)))


class SeededEpisodes(gym.Wrapper):
    """Seeds training episode ``k`` with ``episode_seed(run_seed, k)`` and keeps the open episode's actions.

    The seed SB3's vectorised env passes on reset is ignored on purpose: this wrapper owns training
    seeds, so they do not depend on how SB3 chunks learning. Finished episodes are queued as
    ``(return, length, success, env_steps)`` for the trainer to drain.
    """

    def __init__(self, env: gym.Env, run_seed: int):
        super().__init__(env)
        self.run_seed = int(run_seed)
        self.started = 0                   # training episodes reset so far
        self.steps = 0                     # training env steps so far
        self.actions: list[np.ndarray] = []
        self.tally = EpisodeTally(0)       # the open episode (its success counts from the steps)
        self.finished: list[tuple[float, int, bool, int]] = []

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        obs, info = reset_episode(self.env, self.run_seed, self.started, options=options)
        self.tally = EpisodeTally(self.started)
        self.started += 1
        self.actions = []
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.actions.append(np.array(action, copy=True))
        self.tally.step(reward, info)
        self.steps += 1
        if terminated or truncated:
            self.finished.append((self.tally.ret, len(self.actions), self.tally.success, self.steps))
        return obs, reward, terminated, truncated, info

    def replay(self, episode: int, actions: list[np.ndarray], steps_before: int) -> np.ndarray:
        """Rebuild the env state of training episode ``episode`` after ``actions`` (for resume)."""
        self.started, self.steps = episode, steps_before
        obs, _ = self.reset()
        for a in actions:
            obs, _, terminated, truncated, _ = self.step(a)
            if terminated or truncated:
                raise RuntimeError("replaying the open episode ended it early: the task is not deterministic "
                                   "under its seed, so this checkpoint cannot be resumed exactly")
        return obs


class _CapturingLogger(SB3Logger):
    """An SB3 logger with no outputs that keeps the last value of every ``train/*`` scalar."""

    def __init__(self) -> None:
        super().__init__(folder=None, output_formats=[])
        self.latest: dict[str, float] = {}

    def _capture(self) -> None:
        for k, v in self.name_to_value.items():
            if k.startswith("train/") and isinstance(v, (int, float, np.number)) and k != "train/n_updates":
                self.latest[k] = float(v)

    def dump(self, step: int = 0) -> None:
        self._capture()
        super().dump(step)


class SB3Config:
    """Trainer settings (not SB3's): the budget and the size of one learning unit."""

    def __init__(self, total_steps: int, unit_steps: int):
        self.total_steps = int(total_steps)
        self.unit_steps = int(unit_steps)


class SB3Trainer:
    """The trainer protocol around one SB3 algorithm (see the module docstring)."""

    def __init__(self, algo: type[BaseAlgorithm], env: gym.Env, kwargs: dict[str, Any], seed: int,
                 total_steps: int, unit_steps: int | None = None):
        self.seed = int(seed)
        self.episodes = 0
        self.wrapper = SeededEpisodes(env, self.seed)
        self.vec_env = DummyVecEnv([lambda: self.wrapper])
        self._rng: dict[str, Any] | None = None
        self._dirty = False                # an evaluation used the env since the last training step
        sb3_seed = stream_seed(self.seed, SB3_STREAM) % (2**31)
        with self._sandbox():
            # SB3 seeds the (sandboxed) global RNGs and the action space from ``seed`` and draws its
            # initial weights from them
            self.model = algo(env=self.vec_env, seed=sb3_seed, verbose=0, device="cpu", **kwargs)
        self.logger = _CapturingLogger()
        self.model.set_logger(self.logger)
        self.off_policy = isinstance(self.model, OffPolicyAlgorithm)
        if unit_steps is None:
            unit_steps = self._default_unit()
        self.cfg = SB3Config(total_steps, unit_steps)

    def _default_unit(self) -> int:
        if self.off_policy:
            freq = self.model.train_freq
            if freq.unit.value != "step":
                raise ValueError("flat baselines need train_freq counted in steps, e.g. train_freq: 4")
            return int(freq.frequency) * max(1, 256 // int(freq.frequency))
        return int(self.model.n_steps) * self.vec_env.num_envs

    @property
    def env_steps(self) -> int:
        return int(self.model.num_timesteps)

    # -- global RNG isolation -------------------------------------------------------------------------
    @contextlib.contextmanager
    def _sandbox(self) -> Iterator[None]:
        outer = (random.getstate(), np.random.get_state(), torch.get_rng_state())
        if self._rng is not None:
            random.setstate(self._rng["python"])
            np.random.set_state(self._rng["numpy"])
            torch.set_rng_state(self._rng["torch"])
        try:
            yield
        finally:
            self._rng = {"python": random.getstate(), "numpy": np.random.get_state(),
                         "torch": torch.get_rng_state()}
            random.setstate(outer[0])
            np.random.set_state(outer[1])
            torch.set_rng_state(outer[2])

    # -- trainer protocol ----------------------------------------------------------------------------
    def _restore_open_episode(self) -> None:
        w = self.wrapper
        obs = w.replay(self.episodes, list(w.actions), w.steps - len(w.actions))
        self.model._last_obs = obs[None].copy()
        self.model._last_original_obs = self.model._last_obs
        self.model._last_episode_starts = np.array([len(w.actions) == 0])
        self._dirty = False

    def _explore_eps(self) -> float:
        if isinstance(self.model, DQN):
            return float(self.model.exploration_rate)
        noise = getattr(self.model, "action_noise", None)
        if isinstance(noise, NormalActionNoise):
            return float(np.mean(noise._sigma))
        return 0.0      # PPO explores through its stochastic policy, not an ε

    def train_chunk(self) -> list[EpisodeStats]:
        """Learn whole SB3 units (a ``train_freq`` block / one PPO rollout) until an episode ends.

        Like the HRL loop, the episode in progress is finished even past the budget, so every chunk
        returns at least one episode.
        """
        if self._dirty and self.model._last_obs is not None:
            self._restore_open_episode()
        out: list[EpisodeStats] = []
        while not out:
            unit = self.cfg.unit_steps
            remaining = self.cfg.total_steps - self.env_steps
            if self.off_policy and remaining > 0:
                unit = min(unit, remaining)
            if self.off_policy:     # whole train_freq blocks, so no collected step goes untrained
                freq = int(self.model.train_freq.frequency)
                unit = max(freq, -(-unit // freq) * freq)
            with self._sandbox():
                self.model.learn(unit, reset_num_timesteps=False, callback=_FixBudget(self.cfg.total_steps))
            self.logger._capture()
            for ret, length, success, steps in self.wrapper.finished:
                out.append(EpisodeStats(episode=self.episodes, env_steps=steps, ret=ret, length=length,
                                        success=success, options=1, explore_eps=self._explore_eps(),
                                        filter_eps=0.0, scalars=dict(self.logger.latest)))
                self.episodes += 1
            self.wrapper.finished.clear()
        return out

    def run_episode(self, train: bool = False, seed: int | None = None) -> EpisodeStats:
        """Greedy evaluation (``deterministic=True``) on the inner env; training resumes where it was."""
        if train:
            raise ValueError("SB3 baselines train through train_chunk(); run_episode is evaluation only")
        env = self.wrapper.env
        self._dirty = True
        obs, info = reset_episode(env, self.seed, SB3_EVAL_EPISODE, seed)
        tally = EpisodeTally(self.episodes)
        tally.note(info)                        # a success reported on reset counts
        done = False
        while not done:
            action, _ = self.model.predict(obs, deterministic=True)
            if isinstance(env.action_space, gym.spaces.Discrete):
                action = int(action)
            obs, reward, terminated, truncated, info = env.step(action)
            tally.step(reward, info)
            done = terminated or truncated
        return tally.stats(self.env_steps, options=1, explore_eps=0.0, filter_eps=0.0)

    # -- checkpointing (plain data only) --------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        m = self.model
        s: dict[str, Any] = {
            "params": m.get_parameters(), "num_timesteps": int(m.num_timesteps), "n_updates": int(m._n_updates),
            "episode_num": int(m._episode_num), "episodes": self.episodes,
            "wrapper": {"steps": self.wrapper.steps, "actions": [a.tolist() for a in self.wrapper.actions]},
            "global_rng": self._rng, "action_space_rng": m.action_space.np_random.bit_generator.state,
            "latest": dict(self.logger.latest),
        }
        if isinstance(m, DQN):
            s["n_calls"] = int(m._n_calls)
            s["exploration_rate"] = float(m.exploration_rate)
        if self.off_policy:
            rb = m.replay_buffer
            n = rb.buffer_size if rb.full else rb.pos
            s["replay"] = {"pos": int(rb.pos), "full": bool(rb.full),
                           **{k: torch.from_numpy(getattr(rb, k)[:n].copy()) for k in _REPLAY_FIELDS
                              if getattr(rb, k) is not None}}    # tensors: an empty array pickles as bytes()
        return s

    def load_state_dict(self, s: dict[str, Any]) -> None:
        m = self.model
        try:
            m.set_parameters(s["params"], exact_match=True, device="cpu")
        except (ValueError, RuntimeError) as exc:
            raise ValueError(f"SB3 parameters do not fit this model ({exc})") from None
        m.num_timesteps, m._n_updates = int(s["num_timesteps"]), int(s["n_updates"])
        m._episode_num, self.episodes = int(s["episode_num"]), int(s["episodes"])
        self._rng = s["global_rng"]
        m.action_space.np_random.bit_generator.state = s["action_space_rng"]
        self.logger.latest = dict(s.get("latest", {}))
        if isinstance(m, DQN):
            m._n_calls = int(s["n_calls"])
            m.exploration_rate = float(s["exploration_rate"])
        if self.off_policy:
            rb, rep = m.replay_buffer, s["replay"]
            for k in _REPLAY_FIELDS:
                if k in rep:
                    arr = getattr(rb, k)
                    stored = np.asarray(rep[k])
                    if arr[: len(stored)].shape != stored.shape:
                        raise ValueError(f"replay field {k!r} has shape {stored.shape}, expected {arr.shape}")
                    arr[: len(stored)] = stored
            rb.pos, rb.full = int(rep["pos"]), bool(rep["full"])
        dtype = self.wrapper.action_space.dtype
        self.wrapper.actions = [np.asarray(a, dtype=dtype) for a in s["wrapper"]["actions"]]
        self.wrapper.steps = int(s["wrapper"]["steps"])
        self._restore_open_episode()


class _FixBudget(BaseCallback):
    """SB3 measures ε / schedule progress against ``_total_timesteps``, which ``learn(unit)`` sets to the
    end of the unit. Pointing it at the run's budget keeps DQN's ε schedule a function of the whole run,
    not of the chunk."""

    def __init__(self, total_steps: int):
        super().__init__(verbose=0)
        self.total_steps = int(total_steps)

    def _on_training_start(self) -> None:
        self.model._total_timesteps = self.total_steps

    def _on_step(self) -> bool:
        return True


# -- builders (named in agents.factory.BUILDERS) -----------------------------------------------------------


def _section(cfg: dict[str, Any], name: str) -> dict[str, Any]:
    section = dict(cfg.get(name, {}))
    unit = section.pop("unit_steps", None)
    section["_unit"] = unit
    return section


def _check_space(env: gym.Env, agent: str, kind: type, hint: str) -> None:
    if not isinstance(env.action_space, kind):
        raise ValueError(f"the {agent} baseline needs {kind.__name__} actions but this task has "
                         f"{type(env.action_space).__name__}; {hint}")


def _build(algo: type[BaseAlgorithm], section_name: str, agent: str, env: gym.Env, cfg: dict[str, Any],
           seed: int, defaults: dict[str, Any]) -> SB3Trainer:
    if section_name not in cfg:
        raise ValueError(f"the {agent} baseline has no hyperparameters for this task family; add a "
                         f"{section_name!r} section to its preset in hubsgo_ppl/agents/presets.py")
    kwargs = {**defaults, **_section(cfg, section_name)}
    unit = kwargs.pop("_unit")
    if "policy_kwargs" in kwargs and "net_arch" in kwargs["policy_kwargs"]:
        kwargs["policy_kwargs"] = {**kwargs["policy_kwargs"], "net_arch": list(kwargs["policy_kwargs"]["net_arch"])}
    try:
        return SB3Trainer(algo, env, kwargs, seed, int(cfg["steps"]), unit)
    except TypeError as exc:
        raise ValueError(f"bad {section_name} setting for {agent}: {exc}; see the SB3 docs of "
                         f"{algo.__name__} for its arguments") from None


def build_dqn(env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> SB3Trainer:
    """SB3 DQN as is (max over the target network in the TD target)."""
    _check_space(env, "dqn", gym.spaces.Discrete, "use td3 for continuous-action tasks")
    return _build(DQN, "dqn", "dqn", env, cfg, seed, {"policy": "MlpPolicy"})


def build_ddqn(env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> SB3Trainer:
    """Flat double DQN (:class:`DoubleDQN`); shares the ``dqn`` preset section."""
    _check_space(env, "ddqn", gym.spaces.Discrete, "use td3 for continuous-action tasks")
    return _build(DoubleDQN, "dqn", "ddqn", env, cfg, seed, {"policy": "MlpPolicy"})


def build_ppo(env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> SB3Trainer:
    """SB3 PPO with one env; a chunk is one whole rollout (learning-rate schedules must be constant)."""
    section = cfg.get("ppo", {})
    for key in ("learning_rate", "clip_range"):
        if key in section and not isinstance(section[key], (int, float)):
            raise ValueError(f"ppo.{key} must be a number: chunked learning measures schedule progress "
                             "per rollout, so schedules are not supported")
    return _build(PPO, "ppo", "ppo", env, cfg, seed, {"policy": "MlpPolicy"})


def build_td3(env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> SB3Trainer:
    """SB3 TD3 with Gaussian action noise (``td3.noise_sigma``, a fraction of the action range)."""
    _check_space(env, "td3", gym.spaces.Box, "use dqn, ddqn or ppo for discrete-action tasks")
    section = dict(cfg.get("td3", {}))
    sigma = float(section.pop("noise_sigma", 0.1))
    n = int(np.prod(env.action_space.shape))
    span = (env.action_space.high - env.action_space.low) / 2.0
    noise = NormalActionNoise(mean=np.zeros(n), sigma=sigma * span.astype(np.float64))
    return _build(TD3, "td3", "td3", env, {**cfg, "td3": section}, seed,
                  {"policy": "MlpPolicy", "action_noise": noise})
