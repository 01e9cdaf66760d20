"""Scripted low level for the robosuite arm tasks: track the sub-goal's target with OSC.

The default low level of the arm tasks, and the fast option for CPU runs and tests (the learned one
is :class:`~hubsgo_ppl.agents.td3_her.GoalTD3`): no learning, pure numpy. Each call
reads the chosen sub-goal's target ``(xyz, gripper)`` from the env (``docs/design.md``) and returns a
proportional OSC_POSITION command towards ``xyz`` with the target's gripper command. Routing
(lift, cross, descend) and gripper timing live in the env's targets, which are re-evaluated on the
current state every step, so the controller itself keeps no per-option state.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ScriptedOSC"]


class ScriptedOSC:
    """Proportional end-effector controller towards ``env.subgoal_target(goal_index)``.

    Args:
        gain: action per metre of position error (1/m). OSC_POSITION maps an action of 1 to a 5 cm
            set-point offset; 20 reaches a 20 cm target in about 15 steps at 20 Hz without overshoot.
        tolerance: errors below this (metres) give zero motion, so the arm holds still at a target.
    """

    def __init__(self, gain: float = 20.0, tolerance: float = 0.002):
        self.gain = float(gain)
        self.tolerance = float(tolerance)

    def reset(self) -> None:
        """A new option starts: nothing to forget (the targets are re-read every step)."""

    def act(self, env, goal_index: int) -> np.ndarray:
        """Action (dx, dy, dz, gripper) in [-1, 1]^4, float32, for sub-goal ``goal_index``."""
        task = env.unwrapped
        if not hasattr(task, "subgoal_target") or not hasattr(task, "eef_position"):
            raise TypeError(f"{type(task).__name__} is not a robosuite sub-goal task; ScriptedOSC needs "
                            f"subgoal_target(i) and eef_position() (hubsgo_ppl.envs.make('stack_cubes'))")
        if env.action_space.shape != (4,):
            raise ValueError(f"ScriptedOSC drives an OSC_POSITION arm (4-d action), this env's action space is "
                             f"{env.action_space.shape}")
        xyz, gripper = task.subgoal_target(goal_index)
        error = np.asarray(xyz, dtype=np.float64) - task.eef_position()
        move = np.zeros(3) if np.linalg.norm(error) < self.tolerance else np.clip(self.gain * error, -1.0, 1.0)
        return np.append(move, np.clip(gripper, -1.0, 1.0)).astype(np.float32)
