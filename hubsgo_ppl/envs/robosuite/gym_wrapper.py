"""Gymnasium face of the robosuite arm tasks: flat float32 observations and the sub-goal interface.

``make_robosuite_task(catalogue)`` is the entry point that ``hubsgo_ppl.envs.register()`` gives every
``family: robosuite`` catalogue. The catalogue's ``options`` pick the task class (``env_class``) and
its settings (``horizon``, ``control_freq``, ...); keyword arguments override them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from ...specs import SpecError
from ..subgoals import Catalogue, load_catalogue
from .base import SubgoalManipulationEnv
from .collect_three_balls import CollectThreeBalls
from .options import positive_options, scene_options
from .push_any_one import PushAnyOne
from .scene_check import SCENE_RESETS, scene_problems
from .stack_cubes import StackCubes

__all__ = ["TASK_CLASSES", "RobosuiteTaskEnv", "make_robosuite_task"]

#: ``options.env_class`` of a catalogue -> task class
TASK_CLASSES: dict[str, type[SubgoalManipulationEnv]] = {
    cls.__name__: cls for cls in (StackCubes, PushAnyOne, CollectThreeBalls)}


class RobosuiteTaskEnv(gym.Env):
    """A robosuite sub-goal task as a Gymnasium env (the contract of ``docs/design.md``).

    ``reset(seed=s)`` re-seeds every random draw of the task (placement, joint noise), so equal seeds
    and equal actions give identical trajectories. ``terminated`` is success, ``truncated`` is the
    horizon. Both infos carry ``subgoals`` (bool array, catalogue order) and ``is_success``.
    """

    metadata = {"render_modes": []}

    def __init__(self, task: SubgoalManipulationEnv):
        self.task = task
        self._keys = task.observation_keys
        low, high = task.action_spec
        self.action_space = gym.spaces.Box(low.astype(np.float32), high.astype(np.float32), dtype=np.float32)
        dim = sum(int(np.size(task._observables[k].obs)) for k in self._keys)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (dim,), dtype=np.float32)

    # ---------------------------------------------------------------- sub-goal interface
    @property
    def subgoal_names(self) -> list[str]:
        return self.task.subgoal_names

    def subgoal_achieved(self) -> np.ndarray:
        return self.task.subgoal_achieved()

    def subgoal_lasting(self) -> np.ndarray:
        return self.task.subgoal_lasting()

    def subgoal_target(self, index: int) -> tuple[np.ndarray, float]:
        return self.task.subgoal_target(index)

    def eef_position(self) -> np.ndarray:
        """End-effector position (what a target's xyz is compared with)."""
        return self.task.eef_position()

    @property
    def horizon(self) -> int:
        return self.task.horizon

    def scene_problems(self, seed: int = 0, resets: int = SCENE_RESETS) -> list[str]:
        """What the scene makes impossible after ``reset(seed=s)``, for the ``resets`` seeds from ``seed`` on
        (each start draws its own placement): objects off the table, targets out of the arm's reach
        (:mod:`.scene_check`), those of the first start that has any; resets the env."""
        found = {}
        for s in range(seed, seed + resets):
            self.reset(seed=s)
            problems = scene_problems(self.task)
            if problems:
                found[s] = problems
        if not found:
            return []
        first, last = min(found), seed + resets - 1
        starts = f"the start of seed {first}" + (f"; {len(found)} of the {resets} starts of seeds {seed}-{last} have "
                                                 "a problem" if resets > 1 else "")
        return [f"{problem} ({starts})" for problem in found[first]]

    # ---------------------------------------------------------------- gymnasium API
    def _flat(self, obs: dict) -> np.ndarray:
        return np.concatenate([np.ravel(obs[k]) for k in self._keys]).astype(np.float32)

    def _info(self, success: bool) -> dict[str, Any]:
        return {"subgoals": self.task.subgoal_achieved(), "is_success": bool(success)}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.task.reseed(seed)
        obs = self.task.reset()
        return self._flat(obs), self._info(self.task._check_success())

    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        if action.shape != self.action_space.shape:
            raise ValueError(f"action has shape {action.shape}; this task takes {self.action_space.shape} "
                             f"(dx, dy, dz, gripper) in [-1, 1]")
        if self.task.timestep >= self.task.horizon:
            raise RuntimeError(f"episode is over (horizon {self.task.horizon} reached); call reset() first")
        obs, reward, _, _ = self.task.step(action)
        success = reward > 0   # the sparse reward is 1 exactly on success
        truncated = self.task.timestep >= self.task.horizon
        return self._flat(obs), float(reward), bool(success), bool(truncated and not success), self._info(success)

    def close(self):
        self.task.close()


def make_robosuite_task(catalogue: str | Path | Catalogue, **kwargs: Any) -> RobosuiteTaskEnv:
    """Build the task a ``family: robosuite`` catalogue describes.

    Args:
        catalogue: path of the catalogue YAML (or a loaded :class:`Catalogue`).
        **kwargs: override the catalogue's ``options`` (e.g. ``horizon=200``, ``seed=0``,
            ``placement_initializer=...``).
    """
    cat = catalogue if isinstance(catalogue, Catalogue) else load_catalogue(catalogue)
    if cat.family != "robosuite":
        raise SpecError(f"{cat.source}: family: {cat.family!r} is not a robosuite task; "
                        f"use hubsgo_ppl.envs.make() for it")
    options = {**cat.options, **kwargs}
    # an override (``--set env.KEY=...``) is checked as the catalogue's own option is; a sampler passed
    # from Python is the one value a catalogue cannot hold
    checked = {k: v for k, v in options.items() if not (k == "placement_initializer" and k in kwargs)}
    positive_options(cat, checked)
    scene_options(cat, checked)
    env_class = options.pop("env_class", None)
    if env_class not in TASK_CLASSES:
        raise SpecError(f"{cat.source}: options.env_class: {env_class!r} is not a robosuite task; "
                        f"use one of: {', '.join(TASK_CLASSES)}")
    cls = TASK_CLASSES[env_class]
    try:
        task = cls(cat, **options)
    except TypeError as exc:
        if "unexpected keyword" not in str(exc):
            raise
        raise SpecError(f"{cat.source}: options: {exc}; allowed options: robots, placement_initializer, horizon, "
                        f"control_freq, seed, initialization_noise, travel_clearance, table_full_size (StackCubes also "
                        f"cubes and pads, PushAnyOne colours, CollectThreeBalls wall_height)") from None
    return RobosuiteTaskEnv(task)
