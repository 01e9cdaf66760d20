"""The shortest solution from every start a maze can draw, found with one search of its states.

A maze with ``options.start: room`` starts each episode on any cell of the start room, in any of the
drawn directions. Planning from each start on its own costs one search per start (minutes on a large
room); here one forward search collects the reachable states and who leads to them, and one backward
search from the goal gives every state's distance at once."""

from __future__ import annotations

from collections import deque
from typing import Any, Callable

from .layout import MazeSpec, MazeState


def steps_from_starts(m: Any, transition: Callable[[Any, MazeState, str], MazeState], starts: list[MazeState],
                      max_states: int) -> list[int | None] | None:
    """Fewest steps from each of ``starts`` to the goal of maze ``m`` (the planner's view of it, moved by
    ``transition``; None for a start that cannot reach it), or None where the search passes ``max_states``
    states."""
    terminal = m.lava | {m.goal}
    leads_here: dict[MazeState, list[MazeState]] = {s: [] for s in starts}
    frontier = deque(leads_here)
    while frontier:
        s = frontier.popleft()
        if s.pos in terminal:   # the episode ended here
            continue
        for name in m.actions:
            t = transition(m, s, name)
            if t not in leads_here:
                leads_here[t] = []
                frontier.append(t)
            leads_here[t].append(s)
        if len(leads_here) > max_states:
            return None
    dist = {s: 0 for s in leads_here if s.pos == m.goal}
    queue = deque(dist)
    while queue:
        t = queue.popleft()
        for s in leads_here[t]:
            if s not in dist:
                dist[s] = dist[t] + 1
                queue.append(s)
    return [dist.get(s) for s in starts]


def room_steps_range(spec: MazeSpec, starts: list[MazeState], m: Any,
                     transition: Callable[[Any, MazeState, str], MazeState],
                     plan: Callable[[MazeState], list | None], max_states: int = 300_000) -> tuple[int, int]:
    """``(fewest, most)`` steps to the goal over every cell of the start room and each of ``starts``'
    directions (``m``, ``transition``: the planner's maze and moves); one ``plan`` per start where the whole
    search passes ``max_states`` states."""
    starts = [s._replace(pos=cell) for cell in spec.layout.start_room() for s in starts]
    steps = steps_from_starts(m, transition, starts, max_states)
    if steps is None:
        steps = [None if p is None else len(p) for p in map(plan, starts)]
    if None in steps:
        raise ValueError(f"{spec.source}: the goal is unreachable from {starts[steps.index(None)]}")
    return min(steps), max(steps)
