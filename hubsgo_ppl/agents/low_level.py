"""Low levels: goal-conditioned policies that act toward the sub-goal g chosen by the high level.

- :class:`GoalDQN` (grids): a goal-conditioned DQN over primitive actions with an intrinsic reward of 1
  for achieving g (Sec. 3.2). One network outputs Q(s, g, a) for every g, and every transition trains
  every sub-goal at once from the env's achievement flags (all-goal relabelling, as in hindsight replay).
- :class:`ScriptedLowLevel` (arms): wraps the scripted OSC controller; it does not learn.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import gymnasium as gym
import numpy as np
import torch

from .buffers import ReplayBuffer
from .nets import TargetNetwork, backward, forward, forward_saved, mlp
from .protocols import Controller, LowLevel, LowLevelBase
from .settings import GoalDQNConfig

__all__ = ["LowLevel", "LowLevelBase", "GoalDQNConfig", "GoalDQN", "ScriptedLowLevel"]


class GoalDQN(LowLevelBase):
    """Goal-conditioned DQN: Q(s, ·, ·) → (N goals × A actions); intrinsic reward 1 on achieving g."""

    learns = True

    def __init__(self, obs_dim: int, n_goals: int, n_actions: int, config: GoalDQNConfig,
                 generator: torch.Generator, rng: np.random.Generator, potential=None):
        self.cfg = config
        if config.shaping and potential is None:
            raise ValueError("low.shaping > 0 needs a potential (the env's subgoal_potential()); "
                             "set low.shaping=0")
        self.potential = potential if config.shaping else None
        self.n_goals, self.n_actions = n_goals, n_actions
        self.rng = rng
        self.net = TargetNetwork(partial(mlp, obs_dim, config.hidden, n_goals * n_actions, generator), config.lr,
                                 config.target_tau, config.grad_clip)
        self.q, self.q_target, self.opt = self.net.online, self.net.target, self.net.opt
        self.buffer = ReplayBuffer(config.buffer_size, rng,
                                   dtypes={"action": np.int64, "before": bool, "after": bool,
                                           "terminated": bool},
                                   obs=(obs_dim,), action=(), next_obs=(obs_dim,), before=(n_goals,),
                                   after=(n_goals,), terminated=())
        self.steps = 0
        self.explored = False               # whether the last act() took a random action
        # (N,) weights of the sub-goals in the TD loss (None: all alike); loop.low_goal_weight sets them
        self.goal_weight: torch.Tensor | None = None

    def _q(self, net: torch.nn.Module, obs: torch.Tensor) -> torch.Tensor:
        """(..., N, A) values of every action towards every sub-goal."""
        return forward(net, obs).view(*obs.shape[:-1], self.n_goals, self.n_actions)

    def act(self, obs: np.ndarray, goal: int, explore_eps: float, env: gym.Env | None = None) -> int:
        """ε-greedy in Q(obs, goal, ·); ``self.explored`` says whether this action was the random one."""
        action = self.random_action(explore_eps)
        return self.greedy(obs, goal) if action is None else action

    def random_action(self, explore_eps: float) -> int | None:
        """The ε-greedy draw: a random action with probability ``explore_eps``, else None (act greedily)."""
        self.explored = bool(self.rng.random() < explore_eps)
        return int(self.rng.integers(self.n_actions)) if self.explored else None

    def greedy(self, obs: np.ndarray, goal: int) -> int:
        """argmax_a Q(obs, goal, a)."""
        with torch.no_grad():
            obs_t = torch.as_tensor(obs, dtype=torch.float32)
            q = self._q(self.q, obs_t)[goal]
        return int(q.argmax())

    def observe(self, obs, action, next_obs, before, after, terminated) -> dict[str, float] | None:
        return self.update() if self.store(obs, action, next_obs, before, after, terminated) else None

    def store(self, obs, action, next_obs, before, after, terminated) -> bool:
        """Add a transition to the replay; whether a gradient step (:meth:`update`) is due."""
        self.buffer.add(obs=obs, action=action, next_obs=next_obs, before=before, after=after,
                        terminated=terminated)
        self.steps += 1
        return len(self.buffer) >= self.cfg.learning_starts and self.steps % self.cfg.train_every == 0

    def update(self) -> dict[str, float]:
        b = self.buffer.sample(self.cfg.batch_size)
        before, after = b["before"], b["after"]
        reward = (after & ~before).float()                               # (B, N) intrinsic, per goal
        done = (reward > 0) | b["terminated"][:, None]
        going = (~done).float()
        if self.potential is not None:                                   # phi = 0 at the end of an option
            phi, phi_next = self.potential(torch.cat([b["obs"], b["next_obs"]])).chunk(2)
            reward = reward + self.cfg.shaping * (self.cfg.gamma * going * phi_next - phi)
        with torch.no_grad():
            q_next = self._q(self.q_target, b["next_obs"]).max(-1).values  # (B, N)
            y = reward + self.cfg.gamma * going * q_next
        weight = (~before).float()          # a goal already achieved is never the option's target
        if self.goal_weight is not None:
            weight = weight * self.goal_weight
        index = b["action"][:, None, None].expand(-1, self.n_goals, 1)
        saved = forward_saved(self.q, b["obs"])
        if saved is None:                   # a network backward() does not cover: autograd
            q_a = self._q(self.q, b["obs"]).gather(2, index).squeeze(2)
            loss = (weight * (q_a - y).pow(2)).sum() / weight.sum().clamp_min(1.0)
            self.net.step(loss)
            return {"low/td_loss": loss.item()}
        with torch.no_grad():               # the same loss, and its gradient as autograd computes it
            out, inputs = saved
            q = out.view(*out.shape[:-1], self.n_goals, self.n_actions)             # (B, N, A)
            diff = q.gather(2, index).squeeze(2) - y
            denom = weight.sum().clamp_min(1.0)
            loss = (weight * diff.pow(2)).sum() / denom
            grad = (torch.ones_like(loss) / denom).expand_as(weight) * weight        # d loss / d (weight * diff^2)
            grad = grad * (2.0 * diff.pow(1.0))                                        # ... / d diff
            grad_q = torch.zeros_like(q).scatter_add_(2, index, grad.unsqueeze(2)).view_as(out)
            self.net.apply(backward(self.q, inputs, grad_q))
        return {"low/td_loss": loss.item()}

    def state_dict(self) -> dict[str, Any]:
        return {**self.net.state_dict(), "buffer": self.buffer.state_dict(), "steps": self.steps,
                "goal_weight": self.goal_weight}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.net.load_state_dict(s)
        self.buffer.load_state_dict(s["buffer"])
        self.steps = int(s["steps"])
        self.goal_weight = s.get("goal_weight")


class ScriptedLowLevel(LowLevelBase):
    """A scripted controller (the OSC one of the arm tasks) as a low level: moves to
    ``subgoal_target(g)``, actuates the gripper.

    It learns nothing (``learns = False``), so the loop never calls an update on it.
    """

    def __init__(self, controller: Controller):
        self.controller = controller

    def act(self, obs: np.ndarray, goal: int, explore_eps: float, env: gym.Env) -> np.ndarray:
        return self.controller.act(env.unwrapped, goal)

    def begin_option(self) -> None:
        self.controller.reset()
