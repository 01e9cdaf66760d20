"""Optimal plans for a maze by breadth-first search over its full symbolic state.

The state is (x, y, direction, carried object, cells of the carriable objects, door states), see
:class:`~hubsgo_ppl.envs.minigrid.layout.MazeState`; the moves are the task's own action subset with
MiniGrid's rules (keys open locked doors of their colour, one object carried at a time, doors and
objects block the way, goal and lava end the episode). Every action costs one step, so BFS gives
the fewest steps, and with MiniGrid's reward ``1 - 0.9 * steps / max_steps`` the best return.
Used for acceptance checks (greedy return >= 0.85 x :func:`optimal_return`) and scripted tests.

    >>> from hubsgo_ppl.envs.minigrid.bfs import optimal_steps
    >>> optimal_steps("keydoor")
    19
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

from ...specs import SpecError
from ..subgoals import Catalogue
from .cardinal import CARDINAL, is_cardinal, primitive, primitives
from .layout import MazeSpec, MazeState, load_maze_spec
from .starts import room_steps_range

__all__ = ["plan", "plan_or_none", "optimal_steps", "optimal_return", "transition", "holds", "shortest_path_cells",
           "check_reachable"]

_DIR_VEC = ((1, 0), (0, 1), (-1, 0), (0, -1))
_MOVES = ("left", "right", "forward")
MAX_STATES = 2_000_000


class _Maze:
    """Static lookup tables of a spec, so each BFS expansion is a few dict/set probes."""

    def __init__(self, spec: MazeSpec, put_back: bool = False):
        lay = spec.layout
        self.spec = spec
        self.walls = lay.walls
        self.lava = lay.lava
        self.goal = lay.goal
        self.door_at = {d.cell: j for j, d in enumerate(lay.doors)}
        self.door_color = tuple(d.color for d in lay.doors)
        self.carriables = tuple((o.type, o.color) for o in lay.carriables)
        self.actions = tuple(spec.options.actions)
        # put_back: an object may be dropped only on the cell it starts on (see check_reachable)
        self.homes = spec.initial_state(0).objects if put_back else None


def transition(spec_or_maze: MazeSpec | _Maze, s: MazeState, action: str) -> MazeState:
    """MiniGrid's step on the symbolic state for one named action (``left``, ``forward``, ...)."""
    m = spec_or_maze if isinstance(spec_or_maze, _Maze) else _Maze(spec_or_maze)
    x, y = s.pos
    if action in CARDINAL:      # turn, then the primitive for what is in front (envs/minigrid/cardinal.py)
        s = s._replace(dir=CARDINAL[action])
        dx, dy = _DIR_VEC[s.dir]
        door = m.door_at.get((x + dx, y + dy))
        front = ("object" if (x + dx, y + dy) in s.objects else
                 "door" if door is not None and s.doors[door] != 2 else "other")
        return transition(m, s, primitive(front, s.carrying >= 0))
    if action == "left":
        return s._replace(dir=(s.dir - 1) % 4)
    if action == "right":
        return s._replace(dir=(s.dir + 1) % 4)
    dx, dy = _DIR_VEC[s.dir]
    front = (x + dx, y + dy)
    door = m.door_at.get(front)
    obj = s.objects.index(front) if front in s.objects else -1
    if action == "forward":
        blocked = front in m.walls or obj >= 0 or (door is not None and s.doors[door] != 2)
        return s if blocked else s._replace(pos=front)
    if action == "pickup":
        if obj >= 0 and s.carrying < 0:
            objects = tuple(None if j == obj else c for j, c in enumerate(s.objects))
            return s._replace(carrying=obj, objects=objects)
        return s
    if action == "drop":
        empty = (front not in m.walls and door is None and obj < 0 and front != m.goal
                 and front not in m.lava)
        if empty and s.carrying >= 0 and (m.homes is None or front == m.homes[s.carrying]):
            objects = tuple(front if j == s.carrying else c for j, c in enumerate(s.objects))
            return s._replace(carrying=-1, objects=objects)
        return s
    if action == "toggle":
        if door is None:
            return s
        state = s.doors[door]
        if state == 0:
            key = ("key", m.door_color[door])
            if s.carrying < 0 or m.carriables[s.carrying] != key:
                return s
            new = 2
        else:
            new = 1 if state == 2 else 2
        return s._replace(doors=tuple(new if j == door else d for j, d in enumerate(s.doors)))
    if action == "done":
        return s
    raise ValueError(f"unknown action {action!r}")


def holds(spec: MazeSpec, s: MazeState, subgoal: int) -> bool:
    """Whether catalogue sub-goal ``subgoal`` holds in ``s`` (the same test as the env's)."""
    p = spec.predicates[subgoal]
    if p.kind in ("at", "goal"):
        return s.pos == p.target
    if p.kind == "carrying":
        lay = spec.layout
        return s.carrying >= 0 and (lay.carriables[s.carrying].type,
                                    lay.carriables[s.carrying].color) == spec.carry_kinds[p.index]
    return s.doors[p.index] == 2


def _resolve(source: Any, start_dir: int | None) -> tuple[MazeSpec, list[MazeState], int]:
    """(spec, start states, steps already taken) for an env or a catalogue/task name/spec."""
    env = getattr(source, "unwrapped", None)
    if env is not None and hasattr(env, "symbolic_state"):
        if env.agent_pos is None or env.agent_dir is None or env.agent_dir < 0:
            raise ValueError("the env has not been reset; call env.reset(seed=...) before planning")
        if start_dir is not None:
            raise ValueError("start_dir is only for catalogues; an env plans from its current state")
        spec = env.spec_maze
        if env.max_steps != spec.max_steps:  # a max_steps= override changes the return
            spec = replace(spec, max_steps=env.max_steps)
        return spec, [env.symbolic_state()], int(env.step_count)
    if isinstance(source, MazeSpec):
        spec = source
    elif isinstance(source, Catalogue):
        spec = load_maze_spec(source)
    else:
        p = Path(source)
        if p.suffix not in (".yaml", ".yml"):
            from .. import get_task  # a task name: resolved by the registry, above this module
            p = get_task(str(source)).catalogue_path
        spec = load_maze_spec(p)
    if start_dir is not None:
        if start_dir not in (0, 1, 2, 3):
            raise ValueError(f"start_dir={start_dir!r}; use 0 (right), 1 (down), 2 (left) or 3 (up)")
        dirs = [start_dir]
    elif spec.options.start_dir == "random":
        dirs = [0, 1, 2, 3]
    else:
        dirs = [{"right": 0, "down": 1, "left": 2, "up": 3}[spec.options.start_dir]]
    return spec, [spec.initial_state(d) for d in dirs], 0


def _bfs(spec: MazeSpec, start: MazeState, done: Callable[[MazeState], bool],
         max_states: int = MAX_STATES, strict: bool = True, moves_only: bool = False,
         put_back: bool = False) -> list[int] | None:
    """The shortest action path from ``start`` to a state where ``done`` holds; None if there is none.
    Past ``max_states`` visited states: RuntimeError, or None with ``strict=False``. ``moves_only``:
    only turns and forward steps, except a last action (pickup, toggle, ...) that makes ``done`` hold.
    ``put_back``: ``drop`` only puts an object back on the cell it starts on."""
    m = _Maze(spec, put_back=put_back)
    if done(start):
        return []
    parent: dict[MazeState, tuple[MazeState, int] | None] = {start: None}
    frontier = deque([start])
    terminal = m.lava | {m.goal}
    while frontier:
        s = frontier.popleft()
        if s.pos in terminal:  # the episode ended here
            continue
        for a, name in enumerate(m.actions):
            t = transition(m, s, name)
            moved = name in _MOVES or (name in CARDINAL and (t.objects, t.doors) == (s.objects, s.doors))
            if t in parent or (moves_only and not moved and not done(t)):
                continue
            parent[t] = (s, a)
            if done(t):
                path = []
                while parent[t] is not None:
                    t, act = parent[t]
                    path.append(act)
                return path[::-1]
            frontier.append(t)
        if len(parent) > max_states:
            if not strict:
                return None
            raise RuntimeError(f"{spec.source}: BFS visited over {max_states} states; the maze is too "
                               f"large to plan exactly")
    return None


def _target(spec: MazeSpec, subgoal: str | int | None) -> Callable[[MazeState], bool]:
    if subgoal is None:
        goal = spec.layout.goal
        return lambda s: s.pos == goal
    names = spec.subgoal_names
    if isinstance(subgoal, str):
        if subgoal not in names:
            raise SpecError(f"{spec.source}: no sub-goal {subgoal!r}; use one of: {', '.join(names)}")
        idx = names.index(subgoal)
    else:
        idx = int(subgoal)
        if not 0 <= idx < len(names):
            raise IndexError(f"sub-goal index {subgoal} out of range; the task has {len(names)}: {names}")
    return lambda s: holds(spec, s, idx)


def plan(source: Any, subgoal: str | int | None = None, start_dir: int | None = None) -> list[int]:
    """Shortest action sequence (indices into the task's action space) to the goal, or until the
    named sub-goal first holds.

    ``source`` is a reset :class:`MazeEnv` (plans from its current state), a task name, a catalogue
    path, a :class:`Catalogue` or a :class:`MazeSpec` (plans from the start). A task whose start
    direction is random needs ``start_dir``. Raises ``ValueError`` if the target is unreachable.
    """
    spec, starts, _ = _resolve(source, start_dir)
    if len(starts) > 1:
        raise ValueError(f"{spec.source}: the start direction is random (options.start_dir); pass "
                         f"start_dir=0..3 or plan from a reset env")
    path = _bfs(spec, starts[0], _target(spec, subgoal))
    if path is None:
        what = "the goal" if subgoal is None else f"sub-goal {subgoal!r}"
        raise ValueError(f"{spec.source}: {what} is unreachable from {starts[0]}")
    return path


def plan_or_none(env: Any, subgoal: int, max_states: int = MAX_STATES) -> list[int] | None:
    """The shortest way from a reset env's current state to catalogue sub-goal ``subgoal`` by moving
    (turns and forward steps) and, last, one action that makes the sub-goal hold (picking up its key,
    opening its door); None where there is none or the search passes ``max_states`` states. Keys and
    doors on the way are left as they are: reaching the goal behind a closed door is not one option.
    (A scripted low level's query; :func:`plan` plans the whole task.)"""
    spec, starts, _ = _resolve(env, None)
    return _bfs(spec, starts[0], _target(spec, subgoal), max_states=max_states, strict=False, moves_only=True)


def optimal_steps(source: Any, start_dir: int | None = None) -> int:
    """Fewest steps to the goal (see :func:`plan` for ``source`` and ``start_dir``)."""
    return len(plan(source, start_dir=start_dir))


def optimal_steps_range(source: Any) -> tuple[int, int]:
    """Fewest steps to the goal over every start the task can draw (each start direction and, with
    ``options.start: room``, each cell of the start room): ``(fewest, most)``, equal where it is fixed."""
    spec, starts, _ = _resolve(source, None)
    if spec.options.start == "room" and getattr(source, "unwrapped", None) is None:
        return room_steps_range(spec, starts, _Maze(spec), transition, lambda s: _bfs(spec, s, _target(spec, None)))
    steps = [optimal_steps(source, start_dir=None if len(starts) == 1 else s.dir) for s in starts]
    return min(steps), max(steps)


def optimal_return(source: Any, start_dir: int | None = None) -> float:
    """Best achievable episode return, ``1 - 0.9 * (steps_taken + steps) / max_steps`` (0 if the goal
    cannot be reached in time). For a random start direction (and no ``start_dir``) it is the mean
    over the four equally likely directions, i.e. the expected optimal return."""
    spec, starts, taken = _resolve(source, start_dir)
    goal = spec.layout.goal
    values = []
    for s in starts:
        path = _bfs(spec, s, lambda t: t.pos == goal)
        n = None if path is None else taken + len(path)
        values.append(0.0 if n is None or n > spec.max_steps else 1.0 - 0.9 * n / spec.max_steps)
    return float(sum(values) / len(values))


def shortest_path_cells(source: Any, slack: int = 0) -> set[tuple[int, int]]:
    """The cells the agent occupies on some plan from the start to the goal of at most ``optimum +
    slack`` steps, over every start direction: a cell outside it is off every (near-)shortest path."""
    spec, starts, _ = _resolve(source, None)
    m = _Maze(spec)
    terminal = m.lava | {m.goal}
    dist: dict[MazeState, int] = {s: 0 for s in starts}
    back: dict[MazeState, list[MazeState]] = {}
    frontier = deque(starts)
    while frontier:
        s = frontier.popleft()
        if s.pos in terminal:
            continue
        for name in m.actions:
            t = transition(m, s, name)
            back.setdefault(t, []).append(s)
            if t not in dist:
                dist[t] = dist[s] + 1
                frontier.append(t)
        if len(dist) > MAX_STATES:
            raise RuntimeError(f"{spec.source}: BFS visited over {MAX_STATES} states; the maze is too large")
    goals = [s for s in dist if s.pos == m.goal]
    if not goals:
        raise ValueError(f"{spec.source}: the goal is unreachable")
    optimum = min(dist[s] for s in goals)
    to_goal: dict[MazeState, int] = {s: 0 for s in goals}
    frontier = deque(goals)
    while frontier:
        t = frontier.popleft()
        for s in back.get(t, ()):
            if s not in to_goal:
                to_goal[s] = to_goal[t] + 1
                frontier.append(s)
    return {s.pos for s, d in dist.items() if s in to_goal and d + to_goal[s] <= optimum + slack}


def _relaxed(spec: MazeSpec, start: MazeState) -> tuple[bool, set[int]]:
    """(whether the goal may be reachable, the sub-goals that hold in no reachable state) from
    ``start``, by a relaxation of the maze over cells rather than states.

    The agent walks from its cell over every cell but walls (and the objects' cells where there is no
    ``pickup``: nothing ever moves them), ignoring the objects; lava and the goal end the walk there. It
    holds, all at once, what it carries and every object whose cell it can face; a door is open once it
    is open at the start, or the agent can face it with ``toggle`` and it is unlocked or a key of its
    colour is held. This repeats until nothing changes. It is an over-approximation of
    :func:`transition`: by induction over the actions from ``start``, every reachable state stands on a
    cell the walk reaches (``forward`` only enters a free cell or an open door, and a door can only be
    open as above), carries an object held here (``pickup`` takes an object from in front, from its
    cell at the start or from where it was dropped after being held), and has only doors open that are
    open here (a locked door opens only with its key in hand). So what it does not reach is certainly
    unreachable. A state on lava achieves no sub-goal (its episode has ended); its objects and doors
    are those of the state before it."""
    lay = spec.layout
    acts = set(primitives(spec.options.actions))
    objects, doors = lay.carriables, lay.doors
    door_at = {d.cell: j for j, d in enumerate(doors)}
    blocked = set(lay.walls) if "pickup" in acts else set(lay.walls) | {c for c in start.objects if c}
    opened = [d == 2 for d in start.doors]
    goal = start.pos == lay.goal
    ended = goal or start.pos in lay.lava
    cells: set[tuple[int, int]] = set() if ended else {start.pos}   # where the agent stands, alive, not on the goal
    faced: set[tuple[int, int]] = set()
    while True:
        queue = list(cells)
        for x, y in queue:
            for q in ((x + 1, y), (x, y + 1), (x - 1, y), (x, y - 1)):
                faced.add(q)
                j = door_at.get(q)
                if "forward" not in acts or q in blocked or q in cells or (j is not None and not opened[j]):
                    continue
                if q == lay.goal:
                    goal = True
                elif q not in lay.lava:
                    cells.add(q)
                    queue.append(q)
        held = [k == start.carrying or (c in faced and "pickup" in acts) for k, c in enumerate(start.objects)]
        keys = {o.color for o, h in zip(objects, held) if h and o.type == "key"}
        now = [was or ("toggle" in acts and d.cell in faced and (state != 0 or d.color in keys))
               for was, d, state in zip(opened, doors, start.doors)]
        if now == opened:
            break
        opened = now
    carried = {(o.type, o.color) for o, h in zip(objects, held) if h}

    def possible(p: Any) -> bool:
        if p.kind in ("at", "goal"):
            return p.target in cells or (goal and p.target == lay.goal)
        if p.kind == "carrying":
            return spec.carry_kinds[p.index] in carried
        if p.kind == "door_open":
            return opened[p.index]
        return True     # a kind the relaxation does not model may hold

    return goal, {i for i, p in enumerate(spec.predicates) if not possible(p)}


def check_reachable(source: Any, max_states: int = 300_000) -> list[str] | None:
    """Check a maze before training on it: raise :class:`SpecError` (one line) if no sequence of the
    task's actions takes the agent from its start to the goal, and return the names of the catalogue's
    sub-goals that hold in no reachable state (a key behind its own door, a cell walled in or on lava:
    a state on lava achieves nothing, its episode has ended).

    A cheap relaxation comes first (:func:`_relaxed`): whatever it cannot reach no state reaches, so a
    goal out of its reach raises at once, and the sub-goals out of its reach are certainly returned.
    Then exact searches over the states, each capped at ``max_states``. With a ``drop`` action a key may
    lie on any free cell, which multiplies the states by the cells, so the first search leaves ``drop``
    out, and the second allows it only to put an object back on the cell it starts on (the way to swap
    one key for another). Every state those two reach is reachable in the task too, so where one of
    them reaches the goal and every sub-goal but the relaxation's, the answer is exact. Otherwise (and
    without ``drop``) the whole search runs. If it passes ``max_states`` too, the relaxation's sub-goals
    are returned, or ``None`` where it found nothing wrong: the maze is then not checked exactly."""
    spec, starts, _ = _resolve(source, None)
    names = list(spec.subgoal_names)
    goal = spec.layout.goal
    lava = spec.layout.lava
    goal_possible, never = _relaxed(spec, starts[0])     # the start directions differ only in direction
    if not goal_possible:
        raise _unreachable(spec, starts)
    unmet = set(range(len(names)))
    reached: list[bool] = []

    def visit(s: MazeState) -> bool:    # every reachable state once; never "done", so the search is whole
        if s.pos in lava:
            return False
        unmet.difference_update([i for i in unmet if holds(spec, s, i)])
        if s.pos == goal:
            reached.append(True)
        return False

    def search(maze: MazeSpec, put_back: bool = False) -> bool:     # False past max_states
        for start in starts:    # one per start direction of a random one; with turns, the first reaches all
            try:
                _bfs(maze, start, visit, max_states=max_states, put_back=put_back)
            except RuntimeError:
                return False
            if reached:
                break
        return True

    actions = list(spec.options.actions)
    if "drop" in actions:
        kept = [a for a in actions if a != "drop"]
        if search(replace(spec, options=spec.options.model_copy(update={"actions": kept}))) and reached \
                and unmet <= never:
            return [names[i] for i in sorted(unmet)]
        if search(spec, put_back=True) and reached and unmet <= never:
            return [names[i] for i in sorted(unmet)]
    if not search(spec):
        return [names[i] for i in sorted(never)] or None
    if not reached:
        raise _unreachable(spec, starts)
    return [names[i] for i in sorted(unmet)]


def _drop_would_reach(spec: MazeSpec, start: MazeState, max_states: int = 200_000) -> bool:
    """Whether the goal, unreachable with the task's actions, is reached once ``drop`` is added (a maze
    that needs two objects held one after the other); False where it is there already, where there is
    no pickup, where the actions are the cardinal set (it has no drop), or past ``max_states``."""
    actions = list(spec.options.actions)
    if "drop" in actions or is_cardinal(actions) or "pickup" not in primitives(actions) or len(spec.layout.carriables) < 2:
        return False
    with_drop = replace(spec, options=spec.options.model_copy(update={"actions": [*actions, "drop"]}))
    goal = spec.layout.goal
    try:
        return _bfs(with_drop, start, lambda s: s.pos == goal, max_states=max_states, put_back=True) is not None
    except RuntimeError:
        return False


def _unreachable(spec: MazeSpec, starts: list[MazeState]) -> SpecError:
    acts = primitives(spec.options.actions)
    closed = any(d != 2 for d in starts[0].doors)
    locked = any(d == 0 for d in starts[0].doors)
    if closed and "toggle" not in acts:
        hint = "there is no toggle action, so no closed door can be opened; add toggle to options.actions"
    elif locked and _drop_would_reach(spec, starts[0]):
        hint = ("the agent holds one object at a time and there is no drop action, so it cannot put a key "
                "down to take the next one; add drop to options.actions")
    elif locked:
        hint = "check that every locked door on the way has its key on the agent's side of it"
    else:
        hint = "walls or lava cut the start off from the goal; open a gap"
    if "forward" not in acts:
        hint = "there is no forward action, so the agent cannot move; add forward to options.actions"
    return SpecError(f"{spec.source}: the goal {spec.layout.goal} cannot be reached from the start "
                     f"{starts[0].pos} with the actions {', '.join(spec.options.actions)}; {hint}")
