"""Sub-goal kinds on MiniGrid layouts that change at every reset (catalogues with ``options.gym_id``).

A kind is a predicate over the live grid and a target cell for the low level, both read from a
:class:`Scene` (the objects where they lie now, what the agent carries, what was true at reset).
Arguments that select objects (``type``, ``color``, ``locked``) are all optional: one that is not
given matches any object, so ``carrying {type: key}`` holds for a key of any colour and
``door_open {}`` for any open door. Targets are recomputed from the scene at every call: the nearest
matching object by Manhattan distance from the agent (reading order breaks ties), or the agent's own
cell where nothing is left to reach. docs/minigrid.md is the catalogue reference.

=========================================  ===============================================================
kind and args                              holds when / target
=========================================  ===============================================================
``goal {}``                                the environment reports success (MiniGrid's positive reward on
                                           termination) / the goal square, else the mission's object or cell,
                                           else the last object the mission text names ("the red ball")
``carrying {type?, color?}``               the agent carries a matching object / the nearest one on the floor,
                                           else the nearest box that holds one
``door_open {color?, locked?, route?}``    a matching door is open (``locked: true``: one locked at reset;
                                           ``route: k``: the k-th door on the shortest walk from the start to
                                           the goal's target) / the nearest matching closed door
``box_open {color?}``                      a box present at reset has been opened (toggled away) / that box
``cleared {type?, color?}``                no matching key, ball or box lies next to a door (a blocked
                                           doorway is free) / the nearest object that still blocks one
``in_room {type, color?}``                 the agent is in the room of a matching object (rooms: the floor
                                           split by walls, lava, doors and one-cell gaps in a wall or a river
                                           of lava) / that object
``at {cell: [x, y]}``                      the agent stands on the cell / the cell
``at {type, color?, locked?}``             the agent stands on or next to a matching object / the nearest one
``facing {type, color?, locked?}``         the cell in front of the agent holds a matching object / the
                                           nearest one
``placed_near {type?, color?, near}``      a matching object lies on the floor within one cell (diagonals
                                           too) of another that ``near: {type?, color?}`` matches / while one
                                           is carried, the nearest ``near`` object, else the nearest one
=========================================  ===============================================================
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Literal

import re

import numpy as np
from minigrid.core.constants import COLOR_NAMES
from pydantic import BaseModel, ValidationError, field_validator, model_validator

from ...specs import SpecError, StrictModel, format_validation_error
from .layout import colour_ok

__all__ = ["KINDS", "Scene", "Kind", "compile_kind", "scan", "regions", "route_doors", "goal_cell", "new_scene"]

Cell = tuple[int, int]
_NEIGHBOURS = ((1, 0), (0, 1), (-1, 0), (0, -1))
_CARRIABLE = ("key", "ball", "box")


class _Selector(StrictModel):
    """Which objects an argument set matches; an argument not given matches any."""

    type: Literal["key", "ball", "box", "door", "goal", "lava"] | None = None
    color: str | None = None
    locked: bool | None = None

    _colour_ok = field_validator("color")(classmethod(lambda cls, v: colour_ok(v)))

    @model_validator(mode="after")
    def _locked_is_for_doors(self) -> _Selector:
        if self.locked is not None and self.type not in (None, "door"):
            raise ValueError(f"locked applies to doors only, not to a {self.type}; drop it")
        return self


class _CarryingArgs(_Selector):
    type: Literal["key", "ball", "box"] | None = None


class _DoorArgs(_Selector):
    type: Literal["door"] = "door"
    route: int | None = None

    @field_validator("route")
    @classmethod
    def _route_ok(cls, v: int | None) -> int | None:
        if v is not None and v < 1:
            raise ValueError(f"route: {v} counts doors from 1 (the first door on the way to the goal)")
        return v


class _BoxArgs(_Selector):
    type: Literal["box"] = "box"


class _InRoomArgs(_Selector):
    type: Literal["key", "ball", "box", "door", "goal", "lava"]


class _AtArgs(_Selector):
    cell: tuple[int, int] | None = None

    @model_validator(mode="after")
    def _one(self) -> _AtArgs:
        if (self.cell is None) == (self.type is None):
            raise ValueError("give either cell: [x, y] or an object's type (with color, locked if needed)")
        if self.cell is not None and (self.color is not None or self.locked is not None):
            raise ValueError("cell names the place itself; drop color and locked")
        return self


class _FacingArgs(_Selector):
    type: Literal["key", "ball", "box", "door", "goal", "lava"]


class _NearArgs(_CarryingArgs):
    type: Literal["key", "ball", "box"] | None = None
    near: _Selector


class _NoArgs(StrictModel):
    pass


KINDS: dict[str, type[BaseModel]] = {"goal": _NoArgs, "carrying": _CarryingArgs, "door_open": _DoorArgs,
                                     "box_open": _BoxArgs, "cleared": _Selector, "in_room": _InRoomArgs,
                                     "at": _AtArgs, "facing": _FacingArgs, "placed_near": _NearArgs}
_MISSION = re.compile(rf"\b(?:({'|'.join(COLOR_NAMES)}) )?(key|ball|box|door)\b")


def mission_named(mission: Any) -> tuple[str | None, str] | None:
    """(colour or None, type) of the last object a MiniGrid mission names ("go get a blue key" ->
    ('blue', 'key')); None when it names none."""
    found = _MISSION.findall(mission) if isinstance(mission, str) else []
    return (found[-1][0] or None, found[-1][1]) if found else None


@dataclass
class Scene:
    """The live grid as the kinds read it: objects on the floor (walls left out) in reading order, the
    carried object, the agent's cell, success, and what was fixed at reset."""

    width: int
    height: int
    objects: list[tuple[Any, Cell]]
    carrying: Any
    agent: Cell
    success: bool = False
    locked_at_reset: frozenset[int] = frozenset()        # id() of the doors locked at reset
    boxes_at_reset: dict[int, Any] = field(default_factory=dict)    # id() -> each box on the grid at reset
    rooms: np.ndarray | None = None                      # (W, H) room label, -1 off the floor
    route: tuple[int, ...] = ()                          # id() of the doors on the start-goal walk, in order
    mission_obj: Any = None                              # the env's ``obj`` (the object to fetch), if any
    mission_cell: Cell | None = None                     # the env's ``target_pos`` (the cell to go to), if any
    mission_named: tuple[str | None, str] | None = None  # (colour, type) the mission text names last, if any
    front: Cell | None = None                            # the cell in front of the agent
    version: int = 0                                     # raised whenever ``objects`` is read again
    walls: np.ndarray | None = None                      # (W, H) bool
    lava: np.ndarray | None = None                       # (W, H) bool

    def reread(self, grid: Any, carrying: Any) -> None:
        """Read the objects of ``grid`` again (walls and lava stay as at reset)."""
        w = grid.width
        self.objects = [(o, (i % w, i // w)) for i, o in enumerate(grid.grid) if o is not None and o.type != "wall"]
        self.carrying = carrying
        self.version += 1


def new_scene(grid: Any, agent: Cell, carrying: Any = None, mission_obj: Any = None,
              mission_cell: Any = None, mission: str | None = None, front: Cell | None = None) -> Scene:
    """The scene of a freshly reset ``grid`` (a MiniGrid ``Grid``): what is locked, the boxes, the rooms
    and the doors on the way from ``agent`` to the goal are recorded from it."""
    cell = None if mission_cell is None else (int(mission_cell[0]), int(mission_cell[1]))
    s = Scene(grid.width, grid.height, [], None, (int(agent[0]), int(agent[1])), mission_obj=mission_obj,
              mission_cell=cell, mission_named=mission_named(mission),
              front=None if front is None else (int(front[0]), int(front[1])))
    s.objects, s.walls, s.lava = scan(grid)
    s.carrying = carrying
    doors = {cell: id(obj) for obj, cell in s.objects if obj.type == "door"}
    s.locked_at_reset = frozenset(id(obj) for obj, _ in s.objects if obj.type == "door" and obj.is_locked)
    s.boxes_at_reset = {id(obj): obj for obj, _ in s.objects if obj.type == "box"}
    s.rooms = regions(s.walls | s.lava, set(doors))          # a river of lava parts rooms as a wall does
    s.route = route_doors(s.walls, doors, s.agent, goal_cell(s))
    return s


def scan(grid: Any) -> tuple[list[tuple[Any, Cell]], np.ndarray, np.ndarray]:
    """The objects of a MiniGrid ``grid`` other than walls, in reading order, and two (W, H) maps:
    walls, and lava."""
    w = grid.width
    objects: list[tuple[Any, Cell]] = []
    walls = np.zeros((grid.width, grid.height), bool)
    lava = np.zeros_like(walls)
    for i, obj in enumerate(grid.grid):
        if obj is None:
            continue
        x, y = i % w, i // w
        if obj.type == "wall":
            walls[x, y] = True
        else:
            if obj.type == "lava":
                lava[x, y] = True
            objects.append((obj, (x, y)))
    return objects, walls, lava


def regions(walls: np.ndarray, doors: set[Cell]) -> np.ndarray:
    """Rooms: the floor's 4-connected parts once walls, doors and gaps are taken out. A gap is a floor
    cell in a straight wall, i.e. with wall (or the grid's edge) on both sides two cells deep along one
    axis (FourRooms' doorways)."""
    W, H = walls.shape
    p = np.pad(walls, 2, constant_values=True)          # the grid's edge counts as wall

    def shifted(dx: int, dy: int) -> np.ndarray:
        return p[2 + dx:2 + dx + W, 2 + dy:2 + dy + H]

    gaps = ((shifted(-1, 0) & shifted(1, 0) & shifted(-2, 0) & shifted(2, 0))
            | (shifted(0, -1) & shifted(0, 1) & shifted(0, -2) & shifted(0, 2)))
    blocked = walls | gaps
    for x, y in doors:
        blocked[x, y] = True
    free = (~blocked).tolist()                           # plain lists: the walk below indexes cell by cell
    label = [[-1] * H for _ in range(W)]
    n = 0
    for x0 in range(W):
        for y0 in range(H):
            if not free[x0][y0] or label[x0][y0] >= 0:
                continue
            label[x0][y0] = n
            queue = deque([(x0, y0)])
            while queue:
                x, y = queue.popleft()
                for dx, dy in _NEIGHBOURS:
                    u, v = x + dx, y + dy
                    if 0 <= u < W and 0 <= v < H and free[u][v] and label[u][v] < 0:
                        label[u][v] = n
                        queue.append((u, v))
            n += 1
    return np.array(label, np.int32)


def route_doors(walls: np.ndarray, doors: dict[Cell, int], start: Cell, goal: Cell | None) -> tuple[int, ...]:
    """The doors (their ids, ``doors``: cell -> id) on a shortest 4-connected walk from ``start`` to
    ``goal`` through everything but walls, in the order met; () when there is no goal or no walk."""
    if goal is None:
        return ()
    W, H = walls.shape
    wall = walls.tolist()
    parent: dict[Cell, Cell | None] = {start: None}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        if cell == goal:
            break
        for dx, dy in _NEIGHBOURS:
            nxt = (cell[0] + dx, cell[1] + dy)
            if 0 <= nxt[0] < W and 0 <= nxt[1] < H and not wall[nxt[0]][nxt[1]] and nxt not in parent:
                parent[nxt] = cell
                queue.append(nxt)
    if goal not in parent:
        return ()
    path, cell = [], goal
    while cell is not None:
        path.append(cell)
        cell = parent[cell]
    return tuple(doors[c] for c in reversed(path) if c in doors)


def _dist(a: Cell, b: Cell) -> int:
    return abs(a[0] - b[0]) + abs(a[1] - b[1])


def _nearest(s: Scene, cells: list[Cell]) -> Cell:
    return min(cells, key=lambda c: _dist(c, s.agent)) if cells else s.agent


def _matcher(args: _Selector) -> Callable[[Scene, Any], bool]:
    """Whether an object matches ``args``; with no ``type``, of what a carrying kind can hold, a key, ball
    or box, and else of anything on the floor."""
    t, c, locked = args.type, args.color, args.locked
    types = _CARRIABLE if t is None and isinstance(args, _CarryingArgs) else None

    def match(s: Scene, obj: Any) -> bool:
        return ((obj.type == t if t is not None else types is None or obj.type in types)
                and (c is None or obj.color == c)
                and (locked is None or (obj.type == "door" and (id(obj) in s.locked_at_reset) == locked)))

    return match


@dataclass(frozen=True)
class Kind:
    """A compiled sub-goal: ``holds(scene)`` and ``target(scene) -> (x, y)``; ``selects``, the objects it
    needs, each as (what the catalogue names, ``match(scene, obj)``)."""

    name: str
    kind: str
    holds: Callable[[Scene], bool]
    target: Callable[[Scene], Cell]
    selects: tuple[tuple[str, Callable[[Scene, Any], bool]], ...] = ()


def _named(args: _Selector) -> str:
    """What a selector names, in words: 'red key', 'locked door', 'object'."""
    what = args.type or ("key, ball or box" if isinstance(args, _CarryingArgs) else "object")
    return " ".join(w for w in (args.color, "locked" if args.locked else None, what) if w)


def goal_cell(s: Scene) -> Cell | None:
    """The goal square nearest the agent, else the mission's object (carried: the agent's cell), else the
    mission's cell, else the nearest object of the colour and type the mission text names last (carried:
    the agent's cell), else None."""
    goals = [cell for obj, cell in s.objects if obj.type == "goal"]
    if goals:
        return _nearest(s, goals)
    if s.mission_obj is not None:
        if s.mission_obj is s.carrying:
            return s.agent
        for obj, cell in s.objects:
            if obj is s.mission_obj:
                return cell
    if s.mission_cell is not None or s.mission_named is None:
        return s.mission_cell
    colour, kind = s.mission_named
    named = [cell for obj, cell in s.objects if obj.type == kind and colour in (None, obj.color)]
    if named:
        return _nearest(s, named)
    held = s.carrying
    return s.agent if held is not None and held.type == kind and colour in (None, held.color) else None


def _compile(name: str, kind: str, args: Any) -> Kind:
    match = _matcher(args) if isinstance(args, _Selector) else None
    cache: list[Any] = [None, None, []]        # (scene, version) -> the matching objects, reread on a change

    def found(s: Scene) -> list[tuple[Any, Cell]]:
        if cache[0] is not s or cache[1] != s.version:
            cache[:] = [s, s.version, [(obj, cell) for obj, cell in s.objects if match(s, obj)]]
        return cache[2]

    def cells(s: Scene) -> list[Cell]:
        return [cell for _, cell in found(s)]

    if kind == "goal":
        return Kind(name, kind, lambda s: s.success, lambda s: goal_cell(s) or s.agent)
    if kind == "carrying":
        def carry_target(s: Scene) -> Cell:
            if s.carrying is not None and match(s, s.carrying):
                return s.agent
            return _nearest(s, cells(s) or [c for o, c in s.objects if o.type == "box" and o.contains is not None
                                            and match(s, o.contains)])

        return Kind(name, kind, lambda s: s.carrying is not None and match(s, s.carrying), carry_target)
    if kind == "door_open":
        route = args.route

        def doors(s: Scene) -> list[tuple[Any, Cell]]:
            if route is None:
                return found(s)
            return [(o, c) for o, c in found(s) if len(s.route) >= route and id(o) == s.route[route - 1]]

        def door_target(s: Scene) -> Cell:
            mine = doors(s)
            return _nearest(s, [c for o, c in mine if not o.is_open] or [c for _, c in mine])

        return Kind(name, kind, lambda s: any(o.is_open for o, _ in doors(s)), door_target)
    if kind == "box_open":
        def opened(s: Scene) -> bool:
            on_floor = {id(o) for o, _ in s.objects}
            return any(match(s, box) and id(box) not in on_floor and box is not s.carrying
                       for box in s.boxes_at_reset.values())

        def box_target(s: Scene) -> Cell:
            if s.carrying is not None and id(s.carrying) in s.boxes_at_reset:
                return s.agent
            return _nearest(s, [cell for o, cell in found(s) if id(o) in s.boxes_at_reset])

        return Kind(name, kind, opened, box_target)
    if kind == "cleared":
        def blocking(s: Scene) -> list[Cell]:
            doors = {cell for obj, cell in s.objects if obj.type == "door"}
            return [cell for obj, cell in found(s) if obj.type in _CARRIABLE
                    and any((cell[0] + dx, cell[1] + dy) in doors for dx, dy in _NEIGHBOURS)]

        return Kind(name, kind, lambda s: not blocking(s), lambda s: _nearest(s, blocking(s)))
    if kind == "in_room":
        def inside(s: Scene) -> bool:
            room = s.rooms[s.agent] if s.rooms is not None else -1
            return room >= 0 and any(s.rooms[cell] == room for cell in cells(s))

        return Kind(name, kind, inside, lambda s: _nearest(s, cells(s)))
    if kind == "at":
        if args.cell is not None:
            spot = tuple(args.cell)
            return Kind(name, kind, lambda s: s.agent == spot, lambda s: spot)
        return Kind(name, kind, lambda s: any(_dist(c, s.agent) <= 1 for c in cells(s)),
                    lambda s: _nearest(s, cells(s)))
    if kind == "facing":
        return Kind(name, kind, lambda s: s.front is not None and s.front in cells(s),
                    lambda s: _nearest(s, cells(s)))
    if kind == "placed_near":
        near = _matcher(args.near)

        def placed(s: Scene) -> bool:
            anchors = [(o, c) for o, c in s.objects if near(s, o)]
            return any(o is not a and max(abs(c[0] - d[0]), abs(c[1] - d[1])) <= 1
                       for o, c in found(s) if o.type in _CARRIABLE for a, d in anchors)

        def near_target(s: Scene) -> Cell:
            if s.carrying is not None and match(s, s.carrying):
                return _nearest(s, [c for o, c in s.objects if near(s, o)])
            return _nearest(s, [c for o, c in found(s) if o.type in _CARRIABLE])

        return Kind(name, kind, placed, near_target)
    raise AssertionError(kind)


def compile_kind(i: int, sg: Any, source: str) -> Kind:
    """Validate sub-goal ``i`` (a :class:`~hubsgo_ppl.envs.subgoals.SubgoalDef`) and compile it;
    errors name the file, the key and the fix."""
    key = f"subgoals[{i}] ({sg.name})"
    if sg.kind not in KINDS:
        raise SpecError(f"{source}: {key}.kind: unknown kind {sg.kind!r} for a registered MiniGrid environment; "
                        f"use one of: {', '.join(KINDS)}")
    if "cell" in sg.args and sg.kind != "at":
        raise SpecError(f"{source}: {key}.args.cell: the layout changes at every reset, so a {sg.kind} names its "
                        "object by type, color (and locked, route for doors) rather than by cell")
    try:
        args = KINDS[sg.kind].model_validate(sg.args)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err, prefix=f"{key}.args")) from None
    k = _compile(sg.name, sg.kind, args)
    if isinstance(args, _Selector) and not getattr(args, "cell", None):
        sel = ((_named(args), _matcher(args)),)
        if isinstance(args, _DoorArgs) and args.route is not None:     # the k-th door on the way to the goal
            nth, door = args.route, _matcher(args)
            sel = ((f"{_named(args)} (number {nth} on the way to the goal)",
                    lambda s, o: door(s, o) and len(s.route) >= nth and id(o) == s.route[nth - 1]),)
        if isinstance(args, _NearArgs):
            sel += ((_named(args.near), _matcher(args.near)),)
        k = Kind(k.name, k.kind, k.holds, k.target, sel)
    return k
