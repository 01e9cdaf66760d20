"""HIRO (Nachum et al. 2018, "Data-Efficient Hierarchical RL"): our own compact implementation.

A baseline of the paper's Sec. 4.2 that learns its own sub-goals instead of choosing from a catalogue.

- **Goals** are desired changes of a goal part of the state, ``g_t ∈ [-scale, scale]^k``: the agent's
  (x, y) cell on the grids (decoded from the one-hot symbolic observation), the end-effector xyz on
  the arms. Between high-level decisions the goal follows HIRO's transition
  ``h(s, g, s') = s + g - s'`` (on goal dims), so it keeps pointing at the same absolute target.
- **High level:** TD3 over goals, one decision every ``c`` env steps, reward = the sum of env rewards.
- **Low level:** intrinsic reward ``-||s + g - s'||`` (in scale units). On continuous actions it is a
  goal-conditioned TD3; on discrete actions (MiniGrid) a goal-conditioned DQN with a Boltzmann policy
  ``π(a|s,g) ∝ exp(Q(s,g,a)/τ)``, which gives the log-likelihood the correction needs.
- **Off-policy correction:** when a high-level transition is replayed, its goal is relabelled with the
  candidate, among the original goal, the achieved change ``s_{t+c} - s_t`` and ``n`` Gaussian samples
  around it, that maximises the *current* low level's log-likelihood of the actions actually taken,
  ``Σ_i log π_lo(a_i | s_i, g̃_i)`` with ``g̃_i`` rolled forward by ``h`` from the candidate (for the
  deterministic TD3 low level, the Gaussian surrogate ``-½||a_i - μ(s_i, g̃_i)||²``). Rolling the goal
  forward is the step public ports tend to get wrong (they score every step against the initial goal): see
  :func:`goal_sequence` and the constructed test in ``tests/agents/test_hiro.py``.
"""

from __future__ import annotations

from functools import partial
from typing import Any, Callable

import gymnasium as gym
import numpy as np
import torch
from torch.nn import functional as F

from .buffers import ReplayBuffer
from .episode import EpisodeStats, EpisodeTally, reset_episode
from .nets import TargetNetwork, mlp
from .seeding import HIRO_STREAM, seed_sequence
from .settings import HIROConfig, validate
from .td3 import TD3Core, TD3Step

__all__ = ["HIROConfig", "GoalSpace", "goal_space_for", "goal_sequence", "candidate_goals",
           "off_policy_correction", "TD3Core", "GoalDQNLow", "GoalTD3Low", "HIRO", "build_hiro"]


# -- goal space ---------------------------------------------------------------------------------------


class GoalSpace:
    """Maps observations to the goal part of the state, ``achieved(obs) -> (..., k)``."""

    def __init__(self, achieved: Callable[[np.ndarray], np.ndarray], scale: np.ndarray, what: str):
        self.achieved = achieved
        self.scale = np.asarray(scale, dtype=np.float32)
        self.dim = int(self.scale.size)
        self.what = what


def goal_space_for(env: gym.Env, scale: float | None = None) -> GoalSpace:
    """Grids: the agent's (x, y) from the one-hot observation; arms: the end-effector xyz (obs[:3])."""
    u = env.unwrapped
    if hasattr(u, "obs_mode") and hasattr(u, "width"):
        if u.obs_mode != "symbolic":
            raise ValueError("HIRO on grids reads (x, y) from the symbolic observation; "
                             f"this env has obs_mode={u.obs_mode!r}; use obs_mode: symbolic")
        W, H = int(u.width), int(u.height)

        def cell(obs: np.ndarray) -> np.ndarray:
            obs = np.asarray(obs)
            return np.stack([obs[..., :W].argmax(-1), obs[..., W:W + H].argmax(-1)], -1).astype(np.float32)

        s = float(scale if scale is not None else max(W, H) - 3)   # the largest move inside the walls
        return GoalSpace(cell, np.full(2, s), "agent cell (x, y)")
    if hasattr(u, "eef_position"):
        return GoalSpace(lambda obs: np.asarray(obs, dtype=np.float32)[..., :3],
                         np.full(3, float(scale if scale is not None else 0.3)), "end-effector xyz (m)")
    raise ValueError(f"HIRO does not know the goal space of {type(u).__name__}; it supports the MiniGrid "
                     "mazes (agent cell) and the robosuite arm tasks (end-effector position)")


# -- the off-policy correction ---------------------------------------------------------------------------


def goal_sequence(goal: torch.Tensor, achieved: torch.Tensor) -> torch.Tensor:
    """Goals ``g_0..g_{c-1}`` seen by the low level when ``g_0 = goal``, under ``h(s, g, s') = s + g - s'``.

    Args:
        goal: ``(..., k)`` initial goals (e.g. ``(B, K, k)`` candidates).
        achieved: ``(B, c+1, k)`` goal-part states ``s_t .. s_{t+c}`` of the transition.
    Returns:
        ``(..., c, k)``: ``g_i = goal + s_t - s_{t+i}`` (the fixed absolute target ``s_t + goal``).
    """
    rel = achieved[:, :1] - achieved[:, :-1]                    # (B, c, k): s_t - s_{t+i}
    while rel.dim() < goal.dim() + 1:
        rel = rel.unsqueeze(1)
    return goal.unsqueeze(-2) + rel


def candidate_goals(original: np.ndarray, achieved: np.ndarray, n: int, sigma: np.ndarray,
                    scale: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``(B, n + 2, k)``: the original goal, the achieved change ``s_{t+c} - s_t``, and ``n`` samples
    ``N(s_{t+c} - s_t, σ²)``, all clipped to the goal range (Nachum et al. 2018, Sec. 3.3).

    ``achieved`` is ``(B, c+1, k)``; for an episode that ended early, its last valid entry is repeated.
    """
    delta = achieved[:, -1] - achieved[:, 0]
    noise = rng.normal(size=(delta.shape[0], n, delta.shape[1])) * sigma
    cands = np.concatenate([original[:, None], delta[:, None], delta[:, None] + noise], axis=1)
    return np.clip(cands, -scale, scale).astype(np.float32)


def off_policy_correction(log_lik: Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor],
                          obs: torch.Tensor, achieved: torch.Tensor, actions: torch.Tensor, mask: torch.Tensor,
                          candidates: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Relabel high-level goals: the candidate maximising ``Σ_i mask_i log π_lo(a_i | s_i, g̃_i)``.

    Args:
        log_lik: ``(obs (..., D), goals (..., k), actions (..., *A)) -> (...)`` of the current low level.
        obs: ``(B, c, D)``; achieved: ``(B, c+1, k)``; actions: ``(B, c, *A)``; mask: ``(B, c)`` valid steps;
        candidates: ``(B, K, k)``.
    Returns:
        ``(goals (B, k), index (B,))`` of the chosen candidates.
    """
    B, K = candidates.shape[:2]
    goals = goal_sequence(candidates, achieved)                               # (B, K, c, k)
    o = obs.unsqueeze(1).expand(B, K, *obs.shape[1:])
    a = actions.unsqueeze(1).expand(B, K, *actions.shape[1:])
    with torch.no_grad():
        ll = (log_lik(o, goals, a) * mask.unsqueeze(1)).sum(-1)                  # (B, K)
    idx = ll.argmax(dim=1)      # ties -> the earliest, i.e. the original goal is kept when nothing beats it
    return candidates[torch.arange(B), idx], idx


# -- learners ------------------------------------------------------------------------------------------

#: HIRO's checkpoint names of the TD3 core's networks and optimisers
_TD3_KEYS = {"actor": "actor", "critics": "critics", "actor_target": "actor_t", "critics_target": "critics_t",
             "actor_opt": "opt_actor", "critic_opt": "opt_critic"}


def _td3(in_dim: int, out_dim: int, scale: np.ndarray, cfg: HIROConfig, gen: torch.Generator) -> TD3Core:
    """HIRO's TD3: actions in ``[-scale, scale]``, one learning rate."""
    return TD3Core(in_dim, out_dim, cfg.hidden, gen, actor_lr=cfg.lr, critic_lr=cfg.lr, tau=cfg.tau,
                   policy_delay=cfg.policy_delay, target_noise=cfg.policy_noise, target_noise_clip=cfg.noise_clip,
                   scale=scale)


def _td3_state(core: TD3Core) -> dict[str, Any]:
    return core.state_dict(_TD3_KEYS) | {"updates": core.updates}


def _load_td3_state(core: TD3Core, s: dict[str, Any]) -> None:
    core.load_state_dict(s, _TD3_KEYS)
    core.updates = int(s["updates"])


def _td3_stats(step: TD3Step) -> dict[str, float]:
    out = {"critic_loss": step.critic_loss}
    if step.actor_loss is not None:
        out["actor_loss"] = step.actor_loss
    return out


class GoalDQNLow:
    """Discrete low level: ``Q(s, g, ·)`` with a Boltzmann policy (its log-likelihood drives the correction)."""

    discrete = True

    def __init__(self, obs_dim: int, goal_scale: np.ndarray, n_actions: int, cfg: HIROConfig, gen: torch.Generator):
        self.cfg, self.n_actions = cfg, n_actions
        self.scale = torch.as_tensor(goal_scale, dtype=torch.float32)
        self.net = TargetNetwork(partial(mlp, obs_dim + len(goal_scale), cfg.hidden, n_actions, gen), cfg.lr, cfg.tau)
        self.q, self.q_t = self.net.online, self.net.target

    def _in(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        return torch.cat([obs, goal / self.scale], -1)

    def log_lik(self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        logp = F.log_softmax(self.q(self._in(obs, goal)) / self.cfg.temperature, -1)
        return logp.gather(-1, action.long().unsqueeze(-1)).squeeze(-1)

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> int:
        with torch.no_grad():
            q = self.q(self._in(torch.as_tensor(obs), torch.as_tensor(goal)))
        if not explore:
            return int(q.argmax())
        p = torch.softmax(q / self.cfg.temperature, -1).double().numpy()
        return int(rng.choice(self.n_actions, p=p / p.sum()))

    def update(self, b: dict[str, torch.Tensor], noise: torch.Tensor) -> dict[str, float]:
        with torch.no_grad():
            nxt = self._in(b["next_obs"], b["next_goal"])
            a2 = self.q(nxt).argmax(-1, keepdim=True)               # double-Q target
            y = b["reward"] + self.cfg.gamma_low * (1 - b["done"]) * self.q_t(nxt).gather(-1, a2).squeeze(-1)
        q = self.q(self._in(b["obs"], b["goal"])).gather(-1, b["action"].long().unsqueeze(-1)).squeeze(-1)
        loss = F.smooth_l1_loss(q, y)
        self.net.step(loss)
        return {"td_loss": loss.item()}

    def state_dict(self) -> dict[str, Any]:
        return self.net.state_dict(target="q_t")

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.net.load_state_dict(s, target="q_t")


class GoalTD3Low:
    """Continuous low level: goal-conditioned TD3; log-likelihood ``-½||a - μ(s, g)||²`` (HIRO's surrogate)."""

    discrete = False

    def __init__(self, obs_dim: int, goal_scale: np.ndarray, action_space: gym.spaces.Box, cfg: HIROConfig,
                 gen: torch.Generator):
        if not np.allclose(action_space.low, -action_space.high):
            raise ValueError("HIRO's TD3 low level needs a symmetric action box [-a, a]")
        self.cfg = cfg
        self.gscale = torch.as_tensor(goal_scale, dtype=torch.float32)
        self.ascale = np.asarray(action_space.high, dtype=np.float32)
        self.td3 = _td3(obs_dim + len(goal_scale), int(np.prod(action_space.shape)), self.ascale, cfg, gen)

    def _in(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        return torch.cat([obs, goal / self.gscale], -1)

    def log_lik(self, obs: torch.Tensor, goal: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        diff = (action - self.td3.mu(self._in(obs, goal))) / self.td3.scale
        return -0.5 * diff.pow(2).sum(-1)

    def act(self, obs: np.ndarray, goal: np.ndarray, explore: bool, rng: np.random.Generator) -> np.ndarray:
        with torch.no_grad():
            a = self.td3.mu(self._in(torch.as_tensor(obs), torch.as_tensor(goal))).numpy()
        if explore:
            a = a + rng.normal(size=a.shape).astype(np.float32) * self.cfg.low_noise * self.ascale
        return np.clip(a, -self.ascale, self.ascale).astype(np.float32)

    def update(self, b: dict[str, torch.Tensor], noise: torch.Tensor) -> dict[str, float]:
        return _td3_stats(self.td3.update(self._in(b["obs"], b["goal"]), b["action"], b["reward"],
                                          self._in(b["next_obs"], b["next_goal"]),
                                          self.cfg.gamma_low * (1 - b["done"]), noise))

    def state_dict(self) -> dict[str, Any]:
        return _td3_state(self.td3)

    def load_state_dict(self, s: dict[str, Any]) -> None:
        _load_td3_state(self.td3, s)


# -- the agent ---------------------------------------------------------------------------------------------


class HIRO:
    """Two-level HIRO on the trainer protocol of ``experiments.run`` (one training episode per chunk).

    HIRO runs its own training loop, not :class:`~hubsgo_ppl.agents.loop.HRLLoop`: its high level emits
    continuous goals every ``c`` steps instead of choosing from a sub-goal catalogue, so it has no
    options that end on a sub-goal predicate and no filter. It shares with the loop only the episode
    skeleton of :mod:`.episode`."""

    def __init__(self, env: gym.Env, cfg: HIROConfig, seed: int):
        self.env, self.cfg, self.seed = env, cfg, int(seed)
        self.goals = goal_space_for(env, cfg.goal_scale)
        ss = seed_sequence(self.seed, HIRO_STREAM)
        gen = torch.Generator().manual_seed(int(ss.generate_state(1)[0]))
        self.rng = np.random.default_rng(ss.spawn(1)[0])
        obs_dim, k, c = int(np.prod(env.observation_space.shape)), self.goals.dim, cfg.c
        self.high = _td3(obs_dim, k, self.goals.scale, cfg, gen)
        if isinstance(env.action_space, gym.spaces.Discrete):
            self.low: GoalDQNLow | GoalTD3Low = GoalDQNLow(obs_dim, self.goals.scale, int(env.action_space.n), cfg, gen)
            act_shape, act_dtype = (), np.int64
        elif isinstance(env.action_space, gym.spaces.Box):
            self.low = GoalTD3Low(obs_dim, self.goals.scale, env.action_space, cfg, gen)
            act_shape, act_dtype = tuple(env.action_space.shape), np.float32
        else:
            raise ValueError(f"HIRO supports Discrete or Box actions, not {type(env.action_space).__name__}")
        self.act_shape = act_shape
        self.low_buf = ReplayBuffer(cfg.low_buffer, self.rng, dtypes={"action": act_dtype},
                                    obs=(obs_dim,), goal=(k,), action=act_shape, reward=(), next_obs=(obs_dim,),
                                    next_goal=(k,), done=())
        self.high_buf = ReplayBuffer(cfg.high_buffer, self.rng, dtypes={"seq_act": act_dtype},
                                     obs=(obs_dim,), goal=(k,), reward=(), next_obs=(obs_dim,), done=(),
                                     seq_obs=(c, obs_dim), seq_ag=(c + 1, k), seq_act=(c, *act_shape), mask=(c,))
        self.env_steps = 0
        self.episodes = 0
        self.relabelled = [0, 0]      # (replayed high transitions, of which the goal changed)

    def _noise(self, *shape: int) -> torch.Tensor:
        return torch.as_tensor(self.rng.standard_normal(shape), dtype=torch.float32)

    def _high_goal(self, obs: np.ndarray, train: bool) -> np.ndarray:
        scale = self.goals.scale
        if train and len(self.high_buf) < self.cfg.high_learning_starts:
            return self.rng.uniform(-scale, scale).astype(np.float32)
        with torch.no_grad():
            g = self.high.mu(torch.as_tensor(obs)).numpy()
        if train:
            g = g + self.rng.normal(size=g.shape).astype(np.float32) * self.cfg.high_noise * scale
        return np.clip(g, -scale, scale).astype(np.float32)

    def _update_high(self) -> dict[str, float]:
        cfg = self.cfg
        b = self.high_buf.sample(cfg.batch_size)
        cands = candidate_goals(b["goal"].numpy(), b["seq_ag"].numpy(), cfg.candidates,
                                cfg.candidate_sigma * self.goals.scale, self.goals.scale, self.rng)
        goal, idx = off_policy_correction(self.low.log_lik, b["seq_obs"], b["seq_ag"], b["seq_act"], b["mask"],
                                          torch.as_tensor(cands))
        self.relabelled[0] += len(idx)
        self.relabelled[1] += int((idx != 0).sum())
        stats = _td3_stats(self.high.update(b["obs"], goal, b["reward"], b["next_obs"],
                                            cfg.gamma_high * (1 - b["done"]), self._noise(cfg.batch_size, self.goals.dim),
                                            actor_extra=self._actor_extra(b)))
        return ({f"high/{k}": v for k, v in stats.items()} | {"high/relabel_rate": float((idx != 0).float().mean())}
                | self._extra_stats())

    # -- what a variant adds (HIGL, :mod:`.higl`); HIRO adds nothing ---------------------------------------
    def _actor_extra(self, batch: dict[str, torch.Tensor]) -> Callable[[torch.Tensor], torch.Tensor] | None:
        """A term of the high level's actor loss on ``batch``, a function of the proposed goals."""
        return None

    def _extra_stats(self) -> dict[str, float]:
        return {}

    def _visited(self, obs: np.ndarray, ag: np.ndarray, reward: float) -> None:
        """A state reached in training (with the env reward of the step into it, 0 on reset)."""

    def run_episode(self, train: bool = True, seed: int | None = None) -> EpisodeStats:
        env, cfg, c = self.env, self.cfg, self.cfg.c
        obs, info = reset_episode(env, self.seed, self.episodes, seed)
        tally = EpisodeTally(self.episodes, mean=np.mean)
        tally.note(info)                        # HIRO counts a success reported on reset
        obs = np.asarray(obs, dtype=np.float32)
        ag = self.goals.achieved(obs)
        if train:
            self._visited(obs, ag, 0.0)
        options, done = 0, False
        while not done:
            goal0 = self._high_goal(obs, train)
            g, s0, R = goal0.copy(), obs, 0.0
            seq_obs = np.zeros((c, obs.size), np.float32)
            seq_ag = np.zeros((c + 1, self.goals.dim), np.float32)
            seq_act = np.zeros((c, *self.act_shape), self.high_buf.data["seq_act"].dtype)
            mask = np.zeros(c, np.float32)
            seq_ag[0] = ag
            terminated = truncated = False
            for i in range(c):
                action = self.low.act(obs, g, train, self.rng)
                next_obs, reward, terminated, truncated, info = env.step(action)
                next_obs = np.asarray(next_obs, dtype=np.float32)
                next_ag = self.goals.achieved(next_obs)
                next_g = (ag + g - next_ag).astype(np.float32)                  # h(s, g, s')
                seq_obs[i], seq_act[i], mask[i], seq_ag[i + 1:] = obs, action, 1.0, next_ag
                if train:
                    r_lo = -float(np.linalg.norm(next_g / self.goals.scale))
                    self.low_buf.add(obs=obs, goal=g, action=action, reward=r_lo, next_obs=next_obs,
                                     next_goal=next_g, done=float(terminated))
                    self._visited(next_obs, next_ag, float(reward))
                    self.env_steps += 1
                    if len(self.low_buf) >= max(cfg.low_learning_starts, cfg.batch_size):
                        stats = self.low.update(self.low_buf.sample(cfg.batch_size),
                                                self._noise(cfg.batch_size, *self.act_shape))
                        tally.record({f"low/{k}": v for k, v in stats.items()})
                R += float(reward)
                tally.step(reward, info)
                obs, ag, g = next_obs, next_ag, next_g
                if terminated or truncated:
                    break
            options += 1
            done = terminated or truncated
            if train:
                self.high_buf.add(obs=s0, goal=goal0, reward=R, next_obs=obs, done=float(terminated),
                                  seq_obs=seq_obs, seq_ag=seq_ag, seq_act=seq_act, mask=mask)
                if len(self.high_buf) >= max(cfg.high_learning_starts, cfg.batch_size):
                    tally.record(self._update_high())
        if train:
            self.episodes += 1
        return tally.stats(self.env_steps, options, explore_eps=cfg.high_noise if train else 0.0, filter_eps=0.0)

    def train_chunk(self) -> list[EpisodeStats]:
        return [self.run_episode(train=True)]

    def state_dict(self) -> dict[str, Any]:
        return {"env_steps": self.env_steps, "episodes": self.episodes, "rng": self.rng.bit_generator.state,
                "high": _td3_state(self.high), "low": self.low.state_dict(), "relabelled": list(self.relabelled),
                "high_buf": self.high_buf.state_dict(), "low_buf": self.low_buf.state_dict()}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.env_steps, self.episodes = int(s["env_steps"]), int(s["episodes"])
        self.rng.bit_generator.state = s["rng"]
        _load_td3_state(self.high, s["high"])
        self.low.load_state_dict(s["low"])
        self.high_buf.load_state_dict(s["high_buf"])
        self.low_buf.load_state_dict(s["low_buf"])
        self.relabelled = [int(x) for x in s["relabelled"]]


def build_hiro(env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> HIRO:
    """Builder named in ``agents.factory.BUILDERS``; settings from the preset's ``hiro`` section."""
    return HIRO(env, validate("hiro", HIROConfig, dict(cfg.get("hiro", {})), derived={"total_steps": int(cfg["steps"])}), seed)
