"""HIGL (Kim, Seo, Shin, "Landmark-Guided Subgoal Generation in Hierarchical Reinforcement Learning",
NeurIPS 2021): HIRO (:mod:`.hiro`) whose high level is pulled towards landmarks. Our own compact
implementation on the shared TD3 core.

Everything of HIRO is kept (goal space, the two levels, the off-policy correction, the episode loop);
HIGL adds, from :mod:`.landmarks`:

- **Landmarks**, rebuilt every ``graph_every`` high-level actor updates: ``landmarks_coverage`` by
  farthest-point sampling over the goal parts of ``landmark_pool`` states drawn from the low level's
  replay, and ``landmarks_novelty`` least-visited states by goal-space visit counts (cells of side
  ``novelty_cell``).
- **Target:** HIGL is goal-conditioned and plans to the episode's final goal. Our tasks give none, so
  the target is the goal part of the state where the largest env reward was met so far; before any
  reward, the most novel landmark (the planner then guides exploration).
- **Graph:** edge ``i -> j`` is the low level's estimated distance ``-V_lo(s_i, ag_j - ag_i)`` (its
  rewards are ``-||s + g - s'||``, so ``-V`` grows with the way left), edges over ``landmark_cutoff``
  removed; shortest paths by Floyd-Warshall.
- **Landmark loss:** for each replayed high-level state, the landmark on the shortest path to the
  target (:func:`~.landmarks.select_landmark`), its pseudo-landmark at most
  ``landmark_step * scale`` away, and ``landmark_weight * ||(ag + g - l̃) / scale||`` added to the
  high level's TD3 actor loss. HIGL measures this distance in the embedding of HRAC's adjacency
  network with a margin; we measure it in the goal space itself (no adjacency network, no margin).

With ``landmark_weight: 0`` no landmark is ever built and HIGL is HIRO, bit for bit (a test).
"""

from __future__ import annotations

from typing import Any, Callable

import gymnasium as gym
import numpy as np
import torch

from .hiro import HIRO, GoalDQNLow
from .landmarks import (NoveltyCounts, farthest_point_sampling, landmark_loss, pseudo_landmark, select_landmark,
                        shortest_paths)
from .seeding import HIGL_STREAM, stream_rng
from .settings import HIGLConfig, validate

__all__ = ["HIGLConfig", "HIGL", "low_distance", "build_higl"]


def low_distance(low: Any, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """``max(-V_lo(obs, goal), 0)``: the discrete low level's ``max_a Q``, the TD3 one's ``min_i Q_i(·, μ)``."""
    with torch.no_grad():
        if isinstance(low, GoalDQNLow):
            v = low.q(low._in(obs, goal)).max(-1).values
        else:
            x = low._in(obs, goal)
            v = torch.min(*low.td3.q_values(low.td3.critics, x, low.td3.mu(x)))
    return (-v).clamp_min(0.0)


class HIGL(HIRO):
    """HIRO with landmark guidance of the high level (see the module docstring)."""

    def __init__(self, env: gym.Env, cfg: HIGLConfig, seed: int):
        super().__init__(env, cfg, seed)
        self.cfg: HIGLConfig = cfg
        self.landmark_rng = stream_rng(self.seed, HIGL_STREAM)
        obs_dim = int(np.prod(env.observation_space.shape))
        self.novelty = NoveltyCounts(cfg.novelty_cell if cfg.novelty_cell is not None else 1.0, obs_dim, self.goals.dim)
        self.best_reward = 0.0
        self.target: np.ndarray | None = None       # goal part of the best-rewarded state seen
        self.actor_updates = 0                       # high-level actor updates that used the landmarks
        self.graph: dict[str, np.ndarray] | None = None
        self.last_loss = float("nan")

    # -- HIRO's hooks ----------------------------------------------------------------------------------
    def _visited(self, obs: np.ndarray, ag: np.ndarray, reward: float) -> None:
        self.novelty.visit(obs, ag)
        if reward > self.best_reward:
            self.best_reward, self.target = float(reward), np.asarray(ag, dtype=np.float32).copy()

    def _actor_extra(self, batch: dict[str, torch.Tensor]) -> Callable[[torch.Tensor], torch.Tensor] | None:
        if self.cfg.landmark_weight == 0.0:
            return None

        def term(goal: torch.Tensor) -> torch.Tensor:
            if self.graph is None or self.actor_updates % self.cfg.graph_every == 0:
                self.graph = self.build_graph()
            self.actor_updates += 1
            scale = torch.as_tensor(self.goals.scale)
            ag = batch["seq_ag"][:, 0]
            chosen = torch.as_tensor(self.select(batch["obs"], ag))
            target = pseudo_landmark(ag, chosen, torch.as_tensor(self.cfg.landmark_step * self.goals.scale[0]))
            loss = landmark_loss(goal, ag, target, scale)
            self.last_loss = loss.item()
            return self.cfg.landmark_weight * loss

        return term

    def _extra_stats(self) -> dict[str, float]:
        return {"high/landmark_loss": self.last_loss} if np.isfinite(self.last_loss) else {}

    # -- the landmark graph ----------------------------------------------------------------------------------
    def build_graph(self) -> dict[str, np.ndarray]:
        """Landmarks (coverage, then novelty), the target, and each landmark's shortest way to it."""
        cfg, scale = self.cfg, self.goals.scale
        n = min(cfg.landmark_pool, len(self.low_buf))
        idx = self.landmark_rng.integers(0, len(self.low_buf), size=n)
        pool_obs = self.low_buf.data["next_obs"][idx]
        pool_ag = self.goals.achieved(pool_obs)
        keep = farthest_point_sampling(pool_ag / scale, cfg.landmarks_coverage)
        nov_obs, nov_ag = self.novelty.most_novel(cfg.landmarks_novelty)
        obs = np.concatenate([pool_obs[keep], nov_obs]).astype(np.float32)
        ag = np.concatenate([pool_ag[keep], nov_ag]).astype(np.float32)
        target = self.target if self.target is not None else (nov_ag[0] if len(nov_ag) else ag[-1])
        nodes = np.concatenate([ag, target[None]])                      # (L + 1, k): landmarks, target
        L = len(ag)
        o = torch.as_tensor(obs).repeat_interleave(L + 1, 0)
        g = torch.as_tensor(nodes[None, :, :] - ag[:, None, :]).reshape(-1, self.goals.dim)
        d = low_distance(self.low, o, g).reshape(L, L + 1).numpy()
        edges = np.full((L + 1, L + 1), np.inf)
        edges[:L] = d                                                      # the target is a sink
        paths = shortest_paths(edges, cfg.landmark_cutoff)
        return {"nodes": nodes, "to_target": paths[:L, L]}

    def select(self, obs: torch.Tensor, ag: torch.Tensor) -> np.ndarray:
        """``(B, k)``: the goal-space node each state heads for (a landmark or the target)."""
        nodes = self.graph["nodes"]
        B, N = len(obs), len(nodes)
        o = obs.repeat_interleave(N, 0)
        g = (torch.as_tensor(nodes)[None] - ag[:, None]).reshape(-1, self.goals.dim)
        d_cur = low_distance(self.low, o, g).reshape(B, N).numpy()
        return nodes[select_landmark(d_cur, self.graph["to_target"], self.cfg.landmark_cutoff)]

    # -- checkpointing ----------------------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return super().state_dict() | {"higl": {
            "landmark_rng": self.landmark_rng.bit_generator.state, "novelty": self.novelty.state_dict(),
            "best_reward": self.best_reward, "target": None if self.target is None else self.target.copy(),
            "actor_updates": self.actor_updates, "last_loss": self.last_loss,
            "graph": None if self.graph is None else {k: v.copy() for k, v in self.graph.items()}}}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        super().load_state_dict(s)
        h = s["higl"]
        self.landmark_rng.bit_generator.state = h["landmark_rng"]
        self.novelty.load_state_dict(h["novelty"])
        self.best_reward = float(h["best_reward"])
        self.target = None if h["target"] is None else np.asarray(h["target"], dtype=np.float32)
        self.actor_updates, self.last_loss = int(h["actor_updates"]), float(h["last_loss"])
        self.graph = None if h["graph"] is None else {k: np.asarray(v) for k, v in h["graph"].items()}


def build_higl(env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> HIGL:
    """Builder named in ``agents.factory.BUILDERS``; settings from the preset's ``higl`` section."""
    return HIGL(env, validate("higl", HIGLConfig, dict(cfg.get("higl", {})), derived={"total_steps": int(cfg["steps"])}),
                seed)
