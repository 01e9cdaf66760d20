"""The cardinal action set of a maze: ``options.actions: [east, south, west, north]``.

The action set the learned-sub-goal baselines of the paper (HIRO, HIGL) most likely ran on: each
action moves one cell in a compass direction, and what lies in that direction is dealt with on
contact, so no action of its own is needed to pick up or to open:

* a key or a ball, with the hands empty: it is picked up (the agent stays where it is);
* a closed door: it is opened; a locked door only with the key of its colour in hand (otherwise the
  agent stays, as against a wall);
* anything else: the agent steps forward when the cell is free (floor, an open door, the goal, lava)
  and stays where it is otherwise (a wall, an object while carrying one).

Every action turns the agent to face its direction first, so the observation's heading is the last
move's. One action is one MiniGrid step (``step_count``, the reward's discount by elapsed steps and
truncation are MiniGrid's own): the env and the planner (:mod:`.bfs`) carry an action out as the turn
followed by the MiniGrid primitive :func:`primitive` names. The four names may come in any order and
in any subset, but not mixed with MiniGrid's own (``left``, ``forward``, ``pickup``, ...).
"""

from __future__ import annotations

from typing import Sequence

from minigrid.core.actions import Actions
from minigrid.core.world_object import Door

__all__ = ["CARDINAL", "is_cardinal", "primitive", "primitives", "env_action"]

#: compass name -> MiniGrid heading (0 right/east, 1 down/south, 2 left/west, 3 up/north)
CARDINAL = {"east": 0, "south": 1, "west": 2, "north": 3}


def is_cardinal(actions: Sequence[str]) -> bool:
    """Whether an ``options.actions`` list is the cardinal set (a non-empty list of compass names)."""
    return bool(actions) and all(a in CARDINAL for a in actions)


def primitive(front: str, carrying: bool) -> str:
    """The MiniGrid primitive a cardinal move makes after turning, by what it faces.

    Args:
        front: ``"object"`` (a key or ball on the floor), ``"door"`` (a closed or locked door) or
            ``"other"`` (anything else: floor, wall, an open door, goal, lava).
        carrying: whether the agent holds an object.
    """
    if front == "object":
        return "forward" if carrying else "pickup"      # forward into an object: blocked, it stays
    return "toggle" if front == "door" else "forward"


def primitives(actions: Sequence[str]) -> tuple[str, ...]:
    """The MiniGrid primitives an action list can make: its own names, or what cardinal moves use."""
    return ("forward", "pickup", "toggle") if is_cardinal(actions) else tuple(actions)


def env_action(env, direction: int) -> Actions:
    """Turn a :class:`~.maze.MazeEnv` to ``direction`` and return the MiniGrid action to step with."""
    env.agent_dir = direction
    cell = env.grid.get(*env.front_pos)
    if cell is not None and cell.can_pickup():
        front = "object"
    elif isinstance(cell, Door) and not cell.is_open:
        front = "door"
    else:
        front = "other"
    return Actions[primitive(front, env.carrying is not None)]
