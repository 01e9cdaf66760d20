"""Scripted low level for the MiniGrid mazes: follow a shortest plan to the chosen sub-goal.

``hubsgo train MAZE --low-level scripted`` replaces the learned goal-conditioned DQN with this planner,
so that the high level and the critic are measured on their own: every reachable sub-goal is reached
in the fewest steps, and a sub-goal that cannot be reached from the current state (a door whose key is
not held, the goal behind a closed door) costs the whole option. The plan is a breadth-first search
over the maze's symbolic state (:func:`hubsgo_ppl.envs.minigrid.bfs.plan_or_none`), made once per
option.
"""

from __future__ import annotations

from collections import deque

import gymnasium as gym

from ..envs.minigrid.bfs import plan_or_none

__all__ = ["ScriptedMaze"]


class ScriptedMaze:
    """A shortest plan to ``goal_index`` by BFS, from the env's current symbolic state.

    Args:
        max_states: BFS gives up (the sub-goal counts as unreachable) after this many states; it bounds
            the cost of an option towards a sub-goal that cannot be reached, where the search would
            otherwise enumerate every reachable state of the maze.
    """

    def __init__(self, max_states: int = 200_000):
        self.max_states = int(max_states)
        self.reset()

    def reset(self) -> None:
        """A new option starts: forget the plan."""
        self._goal: int | None = None
        self._plan: deque[int] | None = None     # None: not planned yet in this option

    def act(self, env: gym.Env, goal_index: int) -> int:
        """The next action of a shortest plan to sub-goal ``goal_index``; where there is none (the
        sub-goal is unreachable or already holds), a turn, which changes neither what is reachable nor
        any sub-goal. The maze is deterministic and only this controller acts during an option, so the
        plan made at the option's first step stays valid to its end."""
        task = env.unwrapped
        if not hasattr(task, "symbolic_state"):
            raise TypeError(f"{type(task).__name__} is not a maze task; ScriptedMaze plans on MiniGrid mazes "
                            f"(hubsgo_ppl.envs.make('keydoor'))")
        if goal_index != self._goal or self._plan is None:
            self._goal = goal_index
            self._plan = deque(plan_or_none(task, goal_index, max_states=self.max_states) or [])
        if self._plan:
            return int(self._plan.popleft())
        actions = task.spec_maze.options.actions
        return actions.index("left") if "left" in actions else 0
