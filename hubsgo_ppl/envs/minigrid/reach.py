"""Whether a registered MiniGrid layout's goal square can be reached with an action set.

A relaxation over the cells of the live grid, the registered-env counterpart of the ASCII mazes'
``bfs._relaxed``: the agent walks from its cell with ``forward`` over empty cells, floor and open
doors; lava and walls stop it. Objects on the floor (keys, balls, boxes) block their cell unless there
is ``pickup``, which may clear it. It holds, all at once, the key it carries at reset and every key on
a cell it can face (where there is ``pickup``; a key inside a box also needs ``toggle``). A closed door
opens where there is ``toggle`` and it is unlocked or a key of its colour is held. This repeats until
nothing changes. It over-approximates the env's transitions (one object held at a time, a door's key
beyond it, are ignored), so a goal it does not reach is certainly unreachable.
"""

from __future__ import annotations

from typing import Any

from ...specs import SpecError

__all__ = ["goal_reachable", "missing_for_goal", "at_cells"]


def goal_reachable(env: Any, actions: list[str] | set[str]) -> bool | None:
    """Whether a goal square of ``env``'s current layout may be reached with ``actions`` (a reset
    MiniGridEnv); None where the layout has no goal square."""
    grid, acts = env.grid, set(actions)
    goals = {(x, y) for x in range(grid.width) for y in range(grid.height)
             if (c := grid.get(x, y)) is not None and c.type == "goal"}
    if not goals:
        return None
    if "forward" not in acts:
        return False
    carried = env.carrying
    keys = {carried.color} if carried is not None and carried.type == "key" else set()
    opened: set[tuple[int, int]] = set()
    while True:
        cells, faced = {tuple(int(v) for v in env.agent_pos)}, set()
        queue = list(cells)
        while queue:
            x, y = queue.pop()
            for q in ((x + 1, y), (x, y + 1), (x - 1, y), (x, y - 1)):
                if not (0 <= q[0] < grid.width and 0 <= q[1] < grid.height):
                    continue
                faced.add(q)
                if q in goals:
                    return True
                if q not in cells and _passable(grid.get(*q), q in opened, acts):
                    cells.add(q)
                    queue.append(q)
        held = set(keys)
        for q in faced:
            obj = grid.get(*q)
            inner = getattr(obj, "contains", None) if obj is not None and obj.type == "box" else None
            if obj is not None and obj.type == "key" and "pickup" in acts:
                held.add(obj.color)
            if inner is not None and inner.type == "key" and {"pickup", "toggle"} <= acts:
                held.add(inner.color)
        now = {q for q in faced if (d := grid.get(*q)) is not None and d.type == "door" and "toggle" in acts
               and (not d.is_locked or d.color in held)}
        if now <= opened and held <= keys:
            return False
        opened |= now
        keys |= held


def _passable(obj: Any, opened: bool, acts: set[str]) -> bool:
    if obj is None or obj.type == "floor":
        return True
    if obj.type == "door":
        return obj.is_open or opened
    if obj.type in ("key", "ball", "box"):
        return "pickup" in acts
    return False        # wall, lava, and any object the agent cannot step onto or take away


def missing_for_goal(env: Any, actions: list[str]) -> list[str]:
    """The fewest of ``pickup`` and ``toggle`` that, added to ``actions``, let :func:`goal_reachable`
    reach the goal (empty where neither helps)."""
    missing = [a for a in ("toggle", "pickup") if a not in actions]
    for extra in [[a] for a in missing] + [missing]:
        if goal_reachable(env, [*actions, *extra]):
            return extra
    return []


def at_cells(subgoals: list[Any], width: int, height: int, gym_id: str, source: str) -> list[tuple[int, Any]]:
    """The ``at {cell}`` sub-goals as ``(i, (x, y))``; a :class:`SpecError` for a cell outside the grid."""
    found = []
    for i, sg in enumerate(subgoals):
        if sg.kind == "at" and "cell" in sg.args:
            x, y = sg.args["cell"]
            if not (0 <= x < width and 0 <= y < height):
                raise SpecError(f"{source}: subgoals[{i}] ({sg.name}).args.cell: [{x}, {y}] is outside "
                                f"{gym_id}'s {width}x{height} grid; x counts from 0 to {width - 1}, y from 0 to "
                                f"{height - 1}")
            found.append((i, (x, y)))
    return found


def is_wall(env: Any, cell: tuple[int, int]) -> bool:
    """Whether ``cell`` of ``env``'s current layout holds a wall."""
    obj = env.grid.get(*cell)
    return obj is not None and obj.type == "wall"
