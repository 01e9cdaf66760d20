"""The learned low level of the arm tasks: goal-conditioned TD3 with hindsight experience replay.

One of the two low levels of the arm tasks (the other is the scripted
:class:`~hubsgo_ppl.agents.scripted_osc.ScriptedOSC`). The high level picks a sub-goal g; the task
turns it into a target region ``env.unwrapped.subgoal_target(g) = (xyz, gripper)`` (a waypoint
re-evaluated on every step, so routing — lift, cross, descend — stays in the task). This policy learns
to bring the end effector there; the target's gripper command is applied as given (the networks act on
the motion entries of the action only, so exploration never drops a carried object). Its goal input is the
target *relative to the end effector* (plus the gripper command), so one policy serves every sub-goal
of every task.

References:
    Fujimoto, van Hoof, Meger (2018). Addressing Function Approximation Error in Actor-Critic Methods
    (TD3: twin critics, target policy smoothing, delayed actor updates).
    Andrychowicz et al. (2017). Hindsight Experience Replay (sparse reward -1 until the goal is
    reached; the 'future' relabelling strategy with k extra goals per transition, stored eagerly as in
    HER's Algorithm 1).

A goal is ``(position, gripper)``; what a transition *achieved* is the end-effector position after
the step (read from the observation, ``pos_slice``) and the gripper command it applied. It reached a
goal when the position is within ``tolerance`` metres and the gripper command within
``gripper_tolerance`` of the goal's. Transitions are buffered per option (``begin_option`` starts a new
trajectory) and written to the replay with their relabelled copies when the trajectory ends.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.running_mean_std import RunningMeanStd
from torch import nn

from .buffers import ReplayBuffer
from .protocols import LowLevelBase
from .settings import GoalTD3Config, validate
from .td3 import TD3Core

__all__ = ["GoalTD3Config", "GoalTD3", "ObsNormaliser", "her_future_relabel", "goal_reward"]


def goal_reward(achieved_pos: np.ndarray, achieved_grip: np.ndarray | None, goal_pos: np.ndarray,
                goal_grip: np.ndarray | None, tolerance: float, gripper_tolerance: float) -> np.ndarray:
    """HER's sparse reward: 0 where the goal is reached, -1 elsewhere (vectorised over leading dims)."""
    ok = np.linalg.norm(np.asarray(achieved_pos) - np.asarray(goal_pos), axis=-1) < tolerance
    if goal_grip is not None:
        ok &= np.abs(np.asarray(achieved_grip) - np.asarray(goal_grip)) < gripper_tolerance
    return ok.astype(np.float32) - 1.0


def her_future_relabel(achieved: np.ndarray, k: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """HER 'future' strategy on one trajectory of T transitions.

    ``achieved[t]`` is what transition t achieved. For every t it draws ``k`` indices t' uniformly
    from ``[t, T)`` and returns ``(source, goals)``: ``source`` (T*k,) the transition each copy
    relabels and ``goals`` (T*k, D) = ``achieved[t']``, the goal it is relabelled with.
    """
    achieved = np.asarray(achieved)
    T = achieved.shape[0]
    if T == 0 or k == 0:
        return np.zeros(0, dtype=np.int64), np.zeros((0, *achieved.shape[1:]), dtype=achieved.dtype)
    source = np.repeat(np.arange(T), k)
    # t' = t + floor(u * (T - t)) is uniform over {t, ..., T-1}
    future = source + np.floor(rng.random(T * k) * (T - source)).astype(np.int64)
    return source, achieved[future]


def _array(x: Any, dtype: Any = np.float64) -> np.ndarray:
    """A state entry (a tensor, or a numpy array in older checkpoints) as a numpy array of ``dtype``."""
    return np.array(x.numpy() if isinstance(x, torch.Tensor) else x, dtype=dtype)


class ObsNormaliser:
    """Running mean/std of the observation (HER normalises its inputs): Stable-Baselines3's
    ``RunningMeanStd`` (Chan et al.'s parallel update), in float64, with a floor on the std so that
    constant features stay finite, and clipping. Before any data: mean 0, std the floor."""

    STD_FLOOR = 1e-2

    def __init__(self, dim: int, clip: float):
        self.clip = clip
        self.rms = RunningMeanStd(epsilon=0.0, shape=(dim,))
        self.rms.var = np.zeros(dim)

    @property
    def count(self) -> float:
        return float(self.rms.count)

    @property
    def mean(self) -> np.ndarray:
        return self.rms.mean

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(self.rms.var)

    def update(self, x: np.ndarray) -> None:
        self.rms.update(np.asarray(x, dtype=np.float64).reshape(-1, self.rms.mean.size))

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        mean = torch.as_tensor(self.rms.mean, dtype=torch.float32)
        std = torch.as_tensor(self.std + self.STD_FLOOR, dtype=torch.float32)
        return ((x - mean) / std).clamp(-self.clip, self.clip)

    def state_dict(self) -> dict[str, Any]:
        """Tensors and floats only (a checkpoint loads with ``weights_only=True``)."""
        return {"count": self.count, "mean": torch.from_numpy(self.rms.mean.copy()),
                "var": torch.from_numpy(self.rms.var.copy())}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        count = float(s["count"])
        # checkpoints written before the switch to RunningMeanStd hold the sum of squares ("m2")
        var = _array(s["var"]) if "var" in s else _array(s["m2"]) / max(count, 1.0)
        self.rms.count, self.rms.mean, self.rms.var = count, _array(s["mean"]), var


class GoalTD3(LowLevelBase):
    """Goal-conditioned TD3 + HER: the learned low level of the robosuite tasks.

    The loop's low-level protocol: ``act`` (called with the env, from which it reads the sub-goal's
    current target), ``observe`` (stores the transition; trains), ``begin_option`` (a new trajectory
    for the 'future' relabelling), ``state_dict`` / ``load_state_dict`` and ``rng``.

    Args:
        obs_dim: flat observation size.
        action_low, action_high: the env's action bounds.
        pos_slice: ``(start, stop)`` of the end-effector position inside the observation.
        gripper_index: index of the gripper command in the action, or None (no gripper).
        config: hyperparameters.
        generator: seeds the network initialisation and the training noise.
        rng: exploration, replay sampling and relabelling.
    """

    learns = True

    def __init__(self, obs_dim: int, action_low: np.ndarray, action_high: np.ndarray,
                 pos_slice: tuple[int, int], gripper_index: int | None, config: GoalTD3Config,
                 generator: torch.Generator, rng: np.random.Generator):
        self.cfg = config
        self.rng = rng
        self.gen = generator
        self.low = np.asarray(action_low, dtype=np.float32)
        self.high = np.asarray(action_high, dtype=np.float32)
        if self.low.shape != self.high.shape or self.low.ndim != 1 or not (self.high > self.low).all():
            raise ValueError(f"action bounds must be 1-d with high > low, got low={self.low}, high={self.high}")
        self.act_dim = self.low.size
        start, stop = pos_slice
        if not 0 <= start < stop <= obs_dim:
            raise ValueError(f"pos_slice {pos_slice} does not lie inside an observation of size {obs_dim}")
        self.pos = slice(start, stop)
        self.pos_dim = stop - start
        if gripper_index is not None and not 0 <= gripper_index < self.act_dim:
            raise ValueError(f"gripper_index {gripper_index} is not an action index (action size {self.act_dim})")
        self.grip = gripper_index
        self.goal_dim = self.pos_dim + (gripper_index is not None)
        self.obs_dim = obs_dim
        in_dim = (obs_dim if config.use_obs else 0) + self.goal_dim
        # actions in [-1, 1] (mapped to the env's bounds by _scale); HER's returns of -1 per step lie
        # in [-1/(1-γ), 0] (no terminal on reaching), so the TD target is clipped there
        # the networks act on the motion only; the gripper entry of an action is the target's command
        self.motion = np.array([i for i in range(self.act_dim) if i != gripper_index])
        self.td3 = TD3Core(in_dim, self.motion.size, config.hidden, generator, actor_lr=config.actor_lr,
                           critic_lr=config.critic_lr, tau=config.tau, policy_delay=config.policy_delay,
                           target_noise=config.target_noise, target_noise_clip=config.target_noise_clip,
                           action_l2=config.action_l2, target_range=(-1.0 / (1.0 - config.gamma), 0.0),
                           init_order=("actor", "actor_target", "critics", "critics_target"))
        self.norm = ObsNormaliser(obs_dim, config.obs_clip)
        self.buffer = ReplayBuffer(config.buffer_size, rng, obs=(obs_dim,), action=(self.act_dim,),
                                   next_obs=(obs_dim,), goal=(self.goal_dim,), reward=())
        self._traj: dict[str, list[np.ndarray]] = {"obs": [], "action": [], "next_obs": [], "goal": []}
        self._goal: np.ndarray | None = None   # the goal act() last acted towards (observe stores it)
        self.steps = 0

    @property
    def actor(self) -> nn.Module:
        return self.td3.actor

    @property
    def updates(self) -> int:
        return self.td3.updates

    # ------------------------------------------------------------------ construction
    @classmethod
    def for_env(cls, env: gym.Env, low_cfg: dict[str, Any], gen: torch.Generator,
                rng: np.random.Generator) -> "GoalTD3":
        """Build for a robosuite sub-goal task (``agents/factory.py``); ``low_cfg`` holds config fields."""
        config = validate("low", GoalTD3Config, dict(low_cfg))
        if not isinstance(env.action_space, gym.spaces.Box):
            raise TypeError(f"GoalTD3 needs a continuous (Box) action space, got {env.action_space}; "
                            "grid tasks use GoalDQN")
        task = env.unwrapped
        if not hasattr(task, "subgoal_target"):
            raise TypeError(f"{type(task).__name__} has no subgoal_target(i); GoalTD3 drives robosuite "
                            "sub-goal tasks (hubsgo_ppl.envs.make('stack_cubes'))")
        keys = list(getattr(getattr(task, "task", None), "observation_keys", []))
        if not keys or keys[0] != "robot0_eef_pos":
            raise ValueError("GoalTD3.for_env expects the flat observation to start with robot0_eef_pos "
                             f"(the achieved position); this env's keys are {keys or 'unknown'}")
        agent = cls(int(np.prod(env.observation_space.shape)), env.action_space.low, env.action_space.high,
                    (0, 3), env.action_space.shape[0] - 1, config, gen, rng)
        if config.skill is not None:
            agent.load_skill(config.skill)
        return agent

    # ------------------------------------------------------------------ the shipped reach skill
    #: the reach skill's networks: input (relative goal xyz, gripper command), output the motion
    SKILL_SHAPE = {"in_dim": 4, "motion": 3}

    def save_skill(self, path: str, meta: dict[str, Any]) -> None:
        """Write the actor and critics (tensors only) and ``meta`` (plain data) as a skill file."""
        torch.save({"actor": self.td3.actor.state_dict(), "critics": self.td3.critics.state_dict(),
                    "hidden": list(self.cfg.hidden), "meta": meta}, path)

    def load_skill(self, name: str) -> None:
        """Start the actor, the critics and their targets from the shipped skill ``name``."""
        from importlib import resources

        path = resources.files("hubsgo_ppl.agents") / f"{name}_skill.pt"
        with resources.as_file(path) as file:
            state = torch.load(file, map_location="cpu", weights_only=True)
        shape = {"in_dim": self.goal_dim + (self.obs_dim if self.cfg.use_obs else 0), "motion": int(self.motion.size)}
        if shape != self.SKILL_SHAPE or list(self.cfg.hidden) != list(state["hidden"]):
            raise ValueError(f"low.skill={name}: the skill's networks (hidden {state['hidden']}, goal-only input) do not "
                             f"fit this low level (hidden {list(self.cfg.hidden)}, use_obs {self.cfg.use_obs}); "
                             "set low.skill=null to learn from scratch")
        for net, target, key in ((self.td3.actor, self.td3.actor_target, "actor"),
                                 (self.td3.critics, self.td3.critics_target, "critics")):
            net.load_state_dict(state[key])
            target.load_state_dict(state[key])

    # ------------------------------------------------------------------ networks
    def _inputs(self, obs: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """Network input: [normalised obs], goal position relative to the end effector, gripper command."""
        rel = (goal[..., : self.pos_dim] - obs[..., self.pos]) * self.cfg.goal_scale
        parts = [self.norm(obs)] if self.cfg.use_obs else []
        parts += [rel, goal[..., self.pos_dim:]]
        return torch.cat(parts, dim=-1)

    def _scale(self, a: torch.Tensor) -> torch.Tensor:
        """The actor's motion in [-1, 1] (tanh) -> the env's bounds of those action entries."""
        low, high = torch.as_tensor(self.low[self.motion]), torch.as_tensor(self.high[self.motion])
        return low + (a + 1.0) * 0.5 * (high - low)

    def _unscale(self, a: torch.Tensor) -> torch.Tensor:
        """A stored action's motion entries -> [-1, 1]."""
        low, high = torch.as_tensor(self.low[self.motion]), torch.as_tensor(self.high[self.motion])
        return 2.0 * (a[..., self.motion] - low) / (high - low) - 1.0

    # ------------------------------------------------------------------ acting
    def goal_of(self, env: gym.Env, goal_index: int) -> np.ndarray:
        """Goal vector of sub-goal ``goal_index`` on the env's current state: target xyz (+ gripper)."""
        xyz, gripper = env.unwrapped.subgoal_target(goal_index)
        xyz = np.asarray(xyz, dtype=np.float32).reshape(-1)
        if xyz.size != self.pos_dim:
            raise ValueError(f"subgoal_target({goal_index}) gave a {xyz.size}-d position; this policy "
                             f"reaches {self.pos_dim}-d positions")
        return np.append(xyz, np.float32(gripper)) if self.grip is not None else xyz

    def policy(self, obs: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Deterministic action of the actor for ``goal`` (position, [gripper])."""
        with torch.no_grad():
            x = self._inputs(torch.as_tensor(obs, dtype=torch.float32), torch.as_tensor(goal, dtype=torch.float32))
            action = np.zeros(self.act_dim, dtype=np.float32)
            action[self.motion] = self._scale(self.td3.mu(x)).numpy()
            return self._command_gripper(action, goal)

    def _command_gripper(self, action: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The target's gripper command, applied as given: the networks learn the motion only, and
        exploration never opens a hand that carries an object (a random gripper value drops it)."""
        if self.grip is not None:
            action = np.array(action, dtype=np.float32)
            action[self.grip] = np.clip(goal[self.pos_dim], self.low[self.grip], self.high[self.grip])
        return action

    def act(self, obs: np.ndarray, goal_index: int, explore_eps: float, env: gym.Env) -> np.ndarray:
        """Action towards sub-goal ``goal_index``: Gaussian noise of std ``explore_eps * noise_sigma``
        (fraction of the range) and, with probability ``explore_eps * random_eps``, a uniform action;
        the gripper command is the target's either way.
        ``explore_eps = 0`` (greedy evaluation) is deterministic."""
        if not 0.0 <= explore_eps <= 1.0:
            raise ValueError(f"explore_eps must be in [0, 1], got {explore_eps}")
        goal = self.goal_of(env, goal_index)
        self._goal = goal
        if explore_eps > 0 and self.rng.random() < explore_eps * self.cfg.random_eps:
            return self._command_gripper(self.rng.uniform(self.low, self.high).astype(np.float32), goal)
        a = self.policy(obs, goal)
        if explore_eps > 0 and self.cfg.noise_sigma > 0:
            a = a + self.rng.normal(0.0, explore_eps * self.cfg.noise_sigma, self.act_dim) * (self.high - self.low) / 2
        return self._command_gripper(np.clip(a, self.low, self.high).astype(np.float32), goal)

    # ------------------------------------------------------------------ storing
    def achieved(self, action: np.ndarray, next_obs: np.ndarray) -> np.ndarray:
        """What a transition achieved: end-effector position after it (+ the gripper command applied)."""
        pos = np.asarray(next_obs, dtype=np.float32)[..., self.pos]
        if self.grip is None:
            return pos
        return np.concatenate([pos, np.asarray(action, dtype=np.float32)[..., self.grip: self.grip + 1]], -1)

    def reward(self, achieved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """HER reward of reaching ``goal`` given ``achieved`` (both ``(..., goal_dim)``)."""
        g = self.grip is not None
        return goal_reward(achieved[..., : self.pos_dim], achieved[..., self.pos_dim] if g else None,
                           goal[..., : self.pos_dim], goal[..., self.pos_dim] if g else None,
                           self.cfg.tolerance, self.cfg.gripper_tolerance)

    def begin_option(self) -> None:
        """A new option starts: the pending trajectory ends (its relabelled copies go to replay)."""
        self.end_trajectory()

    def end_trajectory(self) -> int:
        """Write the pending trajectory and its HER 'future' copies to replay; returns how many rows."""
        T = len(self._traj["obs"])
        if T == 0:
            return 0
        obs, action, next_obs, goal = (np.stack(self._traj[k]) for k in ("obs", "action", "next_obs", "goal"))
        for k in self._traj:
            self._traj[k].clear()
        achieved = self.achieved(action, next_obs)
        source, her_goals = her_future_relabel(achieved, self.cfg.her_k, self.rng)
        idx = np.concatenate([np.arange(T), source])
        goals = np.concatenate([goal, her_goals])
        rewards = self.reward(achieved[idx], goals)
        for i, g, r in zip(idx, goals, rewards):
            self.buffer.add(obs=obs[i], action=action[i], next_obs=next_obs[i], goal=g, reward=r)
        self.norm.update(obs)
        return len(idx)

    def observe(self, obs, action, next_obs, achieved_before, achieved_after, terminated) -> dict[str, float] | None:
        """Buffer one transition towards the goal ``act`` used; train every ``train_every`` steps.

        The env's sub-goal flags are not needed: the goal is the target region itself, reached or not
        by the end-effector position. ``terminated`` ends the trajectory (the episode is over).
        """
        if self._goal is None:
            raise RuntimeError("observe() before act(): GoalTD3 stores the goal that act() acted towards")
        self._traj["obs"].append(np.asarray(obs, dtype=np.float32))
        self._traj["action"].append(np.asarray(action, dtype=np.float32))
        self._traj["next_obs"].append(np.asarray(next_obs, dtype=np.float32))
        self._traj["goal"].append(self._goal)
        if terminated:
            self.end_trajectory()
        self.steps += 1
        if len(self.buffer) >= max(self.cfg.learning_starts, self.cfg.batch_size) \
                and self.steps % self.cfg.train_every == 0:
            stats = [self.update() for _ in range(self.cfg.gradient_steps)]
            return {k: float(np.mean([s[k] for s in stats if k in s])) for k in stats[-1]}
        return None

    # ------------------------------------------------------------------ learning
    def update(self) -> dict[str, float]:
        """One TD3 step on a replay minibatch (critic; actor and targets every ``policy_delay``)."""
        b = self.buffer.sample(self.cfg.batch_size)
        a_unit = self._unscale(b["action"])
        noise = torch.randn(a_unit.shape, generator=self.gen)
        step = self.td3.update(self._inputs(b["obs"], b["goal"]), a_unit, b["reward"],
                               self._inputs(b["next_obs"], b["goal"]), self.cfg.gamma, noise)
        out = {"low/critic_loss": step.critic_loss, "low/q": step.q, "low/reward": b["reward"].mean().item()}
        if step.actor_loss is not None:
            out["low/actor_loss"] = step.actor_loss
        return out

    # ------------------------------------------------------------------ checkpointing
    def state_dict(self) -> dict[str, Any]:
        """Networks, optimisers, replay, normaliser, pending trajectory and the noise generator's state.

        The pending trajectory and goal are tensors: an empty numpy array pickles as a call to
        ``bytes()``, which a weights-only load refuses."""
        return self.td3.state_dict() | {
            "buffer": self.buffer.state_dict(), "norm": self.norm.state_dict(),
            "traj": {k: torch.from_numpy(np.stack(v)) if v else torch.zeros(0) for k, v in self._traj.items()},
            "goal": None if self._goal is None else torch.from_numpy(self._goal.copy()),
            "gen": self.gen.get_state(), "steps": self.steps, "updates": self.updates}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        self.td3.load_state_dict(s)
        self.buffer.load_state_dict(s["buffer"])
        self.norm.load_state_dict(s["norm"])
        self._traj = {k: list(_array(v, np.float32)) if len(v) else [] for k, v in s["traj"].items()}
        self._goal = None if s["goal"] is None else _array(s["goal"], np.float32)
        self.gen.set_state(s["gen"])
        self.steps, self.td3.updates = int(s["steps"]), int(s["updates"])
