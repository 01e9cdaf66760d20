"""Declarative mazes: an ASCII layout plus the ``options`` and sub-goals of a minigrid catalogue.

A minigrid task is a catalogue YAML (``family: minigrid``) whose ``options`` name an ASCII layout file
(relative to the YAML) and a legend. :func:`load_maze_spec` turns both into a frozen
:class:`MazeSpec`: the grid, the objects, the options and the compiled sub-goal predicates. Every
problem raises :class:`~hubsgo_ppl.specs.SpecError` naming the file, the key (or line) and the fix.

ASCII legend
------------
Row ``y`` of the file is grid row ``y`` (top row is ``y = 0``); column ``x`` is grid column ``x``.

====  ===========================================================================================
char  meaning
====  ===========================================================================================
``#``  wall
``.``  empty floor (a space also works)
``A``  agent start (exactly one; its direction comes from ``options.start_dir``, ``options.start``
       may spread it over A's room)
``G``  goal (exactly one); reaching it ends the episode with the reward
``~``  lava (ends the episode with reward 0)
other  whatever ``options.legend`` maps it to, e.g. ``y: {type: key, color: yellow}``,
       ``Y: {type: door, color: yellow, locked: true}``; legend types: wall, key, ball, door,
       goal, lava
====  ===========================================================================================

Lines starting with ``;`` are comments and are skipped, so each layout can carry its own legend. The
outer border must be wall. Colours are MiniGrid's: red, green, blue, purple, yellow, grey.

Minigrid ``options`` (all validated, unknown keys rejected)::

    layout: keydoor.txt                   # required, relative to the catalogue
    legend: {y: {type: key, color: yellow}, Y: {type: door, color: yellow, locked: true}}
    max_steps: 2000                       # default 4 * width * height
    start_dir: right                      # right | down | left | up | random (seeded by reset)
    start: cell                           # cell: on A | room: a free cell of A's room (seeded by reset)
    actions: [left, right, forward, pickup, toggle]   # subset of MiniGrid's actions, in this order;
                                          # or [east, south, west, north]: move, pick up and open on contact
    obs_mode: symbolic                    # symbolic | image | egocentric
    mission: "reach the green goal"

Sub-goal predicate kinds (``subgoals[i].kind`` with ``args``):

* ``at {cell: [x, y]}``: the agent stands on the cell (not a wall);
* ``carrying {type: key, color: yellow}``: the agent carries such an object (one must exist);
* ``door_open {color: yellow}`` or ``door_open {cell: [x, y]}``: that door is open;
* ``goal {}``: the agent is on the goal cell.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, NamedTuple

from minigrid.core.actions import Actions
from minigrid.core.constants import COLOR_NAMES
from pydantic import BaseModel, Field, ValidationError, field_validator, model_validator

from ...specs import SpecError, StrictModel, format_validation_error
from ..subgoals import Catalogue, load_catalogue
from .cardinal import CARDINAL

__all__ = ["LegendEntry", "MazeOptions", "MazeObject", "Layout", "Predicate", "MazeSpec", "MazeState",
           "PREDICATE_KINDS", "DIRECTIONS", "parse_layout", "load_maze_spec"]

DIRECTIONS = {"right": 0, "down": 1, "left": 2, "up": 3}
PREDICATE_KINDS = ("at", "carrying", "door_open", "goal")
CARRIABLE = ("key", "ball")
COMMENT = ";"

# Built-in characters; a legend may add characters but not redefine these.
_BUILTIN = {"#": "wall", ".": "empty", " ": "empty", "A": "agent", "G": "goal", "~": "lava"}


def colour_ok(v: str | None) -> str | None:
    """A MiniGrid colour name (or None), else a ValueError that lists them."""
    if v is not None and v not in COLOR_NAMES:
        raise ValueError(f"unknown colour {v!r}; use one of: {', '.join(COLOR_NAMES)}")
    return v


class LegendEntry(StrictModel):
    """What one layout character stands for."""

    type: Literal["wall", "key", "ball", "door", "goal", "lava"]
    color: str | None = Field(default=None, description="MiniGrid colour; required for key, ball, door")
    locked: bool = Field(default=False, description="doors only: needs the key of its colour")
    open: bool = Field(default=False, description="doors only: starts open")

    _colour_ok = field_validator("color")(classmethod(lambda cls, v: colour_ok(v)))

    @model_validator(mode="after")
    def _consistent(self) -> LegendEntry:
        if self.type in ("key", "ball", "door") and self.color is None:
            raise ValueError(f"a {self.type} needs a colour; add color: one of {', '.join(COLOR_NAMES)}")
        if self.type != "door" and (self.locked or self.open):
            raise ValueError(f"locked/open only apply to doors, not to a {self.type}; remove them")
        if self.locked and self.open:
            raise ValueError("a door cannot start both locked and open; drop one of them")
        return self


class MazeOptions(StrictModel):
    """The ``options`` mapping of a minigrid catalogue."""

    layout: str = Field(description="ASCII layout file, relative to the catalogue")
    legend: dict[str, LegendEntry] = Field(default_factory=dict)
    max_steps: int | None = Field(default=None, gt=0, description="truncation; default 4*W*H")
    start_dir: Literal["right", "down", "left", "up", "random"] = "right"
    start: Literal["cell", "room"] = Field(
        default="cell", description="cell: every episode starts on A; room: on a free cell of A's room "
                                    "(reachable from A without crossing a door, object or lava; seeded by reset)")
    actions: list[str] = Field(default_factory=lambda: ["left", "right", "forward", "pickup", "toggle"])
    obs_mode: Literal["symbolic", "image", "egocentric"] = "symbolic"
    mission: str = "reach the goal"

    @field_validator("legend")
    @classmethod
    def _legend_chars(cls, v: dict[str, LegendEntry]) -> dict[str, LegendEntry]:
        for ch in v:
            if len(ch) != 1 or ch == COMMENT:
                raise ValueError(f"legend key {ch!r} must be one character other than {COMMENT!r}")
            if ch in _BUILTIN:
                raise ValueError(f"legend key {ch!r} is built in ({_BUILTIN[ch]}); pick another character")
        return v

    @field_validator("actions")
    @classmethod
    def _actions_ok(cls, v: list[str]) -> list[str]:
        known = [a.name for a in Actions]
        bad = [a for a in v if a not in known and a not in CARDINAL]
        if bad:
            raise ValueError(f"unknown action(s) {bad}; use names from: {', '.join(known)}; or the cardinal "
                             f"moves {', '.join(CARDINAL)}")
        if any(a in CARDINAL for a in v) and not all(a in CARDINAL for a in v):
            raise ValueError(f"the cardinal moves ({', '.join(CARDINAL)}) cannot be mixed with MiniGrid's actions")
        if not v or len(set(v)) != len(v):
            raise ValueError("actions must be a non-empty list without repeats")
        return v


class MazeObject(NamedTuple):
    """An object placed by the layout (doors, keys, balls)."""

    type: str
    color: str
    cell: tuple[int, int]
    locked: bool = False
    open: bool = False


@dataclass(frozen=True)
class Layout:
    """A parsed ASCII maze. ``walls``/``lava`` are sets of cells; objects are listed in reading order."""

    width: int
    height: int
    walls: frozenset[tuple[int, int]]
    lava: frozenset[tuple[int, int]]
    agent_start: tuple[int, int]
    goal: tuple[int, int]
    objects: tuple[MazeObject, ...]
    rows: tuple[str, ...]

    @property
    def doors(self) -> tuple[MazeObject, ...]:
        return tuple(o for o in self.objects if o.type == "door")

    @property
    def carriables(self) -> tuple[MazeObject, ...]:
        return tuple(o for o in self.objects if o.type in CARRIABLE)

    def start_room(self) -> tuple[tuple[int, int], ...]:
        """The free cells an agent on ``agent_start`` reaches by walking: no wall, lava, door, object or
        goal on them, 4-connected to ``agent_start`` (first), in breadth-first order. The border is wall
        (parse_layout checks it), so the walk never leaves the grid."""
        blocked = self.walls | self.lava | {o.cell for o in self.objects} | {self.goal}
        seen, queue = {self.agent_start}, [self.agent_start]
        for x, y in queue:
            for cell in ((x + 1, y), (x, y + 1), (x - 1, y), (x, y - 1)):
                if cell not in seen and cell not in blocked:
                    seen.add(cell)
                    queue.append(cell)
        return tuple(queue)

    def object_at(self, cell: tuple[int, int]) -> MazeObject | None:
        for o in self.objects:
            if o.cell == cell:
                return o
        return None


class Predicate(NamedTuple):
    """A compiled sub-goal: its kind, the cell the low level aims at, and what it tests.

    ``index`` is the door index (``door_open``) or the carried-kind index (``carrying``) in
    :attr:`MazeSpec.carry_kinds`; -1 where unused.
    """

    name: str
    kind: str
    target: tuple[int, int]
    index: int = -1


class MazeState(NamedTuple):
    """The full symbolic state of a maze, hashable (used by BFS and by the symbolic observation).

    ``carrying`` is the index into :attr:`Layout.carriables` of the carried object (-1: nothing);
    ``objects`` the cell of each carriable (``None`` while carried); ``doors`` per door
    0 = locked, 1 = closed, 2 = open.
    """

    pos: tuple[int, int]
    dir: int
    carrying: int
    objects: tuple[tuple[int, int] | None, ...]
    doors: tuple[int, ...]


@dataclass(frozen=True)
class MazeSpec:
    """Everything a :class:`~hubsgo_ppl.envs.minigrid.maze.MazeEnv` needs, validated."""

    catalogue: Catalogue
    options: MazeOptions
    layout: Layout
    predicates: tuple[Predicate, ...]
    max_steps: int
    carry_kinds: tuple[tuple[str, str], ...]   # distinct (type, colour) of carriables, for the obs
    # the whole catalogue's predicates (``predicates`` unless the catalogue is a subset of another):
    # the landmarks an egocentric observation measures its offsets to
    landmarks: tuple[Predicate, ...] = ()

    @property
    def source(self) -> str:
        return self.catalogue.source

    @property
    def subgoal_names(self) -> list[str]:
        return [p.name for p in self.predicates]

    def initial_state(self, start_dir: int) -> MazeState:
        lay = self.layout
        return MazeState(lay.agent_start, start_dir, -1, tuple(o.cell for o in lay.carriables),
                         tuple(2 if d.open else (0 if d.locked else 1) for d in lay.doors))


def parse_layout(text: str, legend: dict[str, LegendEntry], source: str = "<layout>") -> Layout:
    """Parse ASCII ``text`` with ``legend``; errors name ``source`` and the line.

    Trailing whitespace is ignored, so pad rows with ``.`` rather than spaces at the end.
    """
    rows: list[tuple[int, str]] = []
    for lineno, line in enumerate(text.splitlines(), start=1):
        if line.startswith(COMMENT):
            continue
        line = line.rstrip()
        if line:
            rows.append((lineno, line))
    if not rows:
        raise SpecError(f"{source}: the layout is empty; draw the maze with '#', '.', 'A', 'G'")
    width = len(rows[0][1])
    for lineno, line in rows:
        if len(line) != width:
            raise SpecError(f"{source}: line {lineno}: row has {len(line)} characters, the first row "
                            f"has {width}; make every row the same width")
    height = len(rows)
    if width < 3 or height < 3:
        raise SpecError(f"{source}: the maze is {width}x{height}; it must be at least 3x3 with a wall border")

    walls, lava, objects = set(), set(), []
    agents, goals = [], []
    known = "".join(sorted(set(_BUILTIN) - {" "})) + "".join(sorted(legend))
    for y, (lineno, line) in enumerate(rows):
        for x, ch in enumerate(line):
            cell = (x, y)
            kind = _BUILTIN.get(ch)
            entry = legend.get(ch)
            if kind is None and entry is None:
                raise SpecError(f"{source}: line {lineno}, column {x + 1}: unknown character {ch!r}; "
                                f"use one of {known!r} or add it to the catalogue's options.legend")
            border = x in (0, width - 1) or y in (0, height - 1)
            is_wall = kind == "wall" or (entry is not None and entry.type == "wall")
            if border and not is_wall:
                raise SpecError(f"{source}: line {lineno}, column {x + 1}: the border must be wall "
                                f"('#'), found {ch!r}")
            t = kind or entry.type
            if t == "wall":
                walls.add(cell)
            elif t == "lava":
                lava.add(cell)
            elif t == "agent":
                agents.append(cell)
            elif t == "goal":
                goals.append(cell)
            elif t in ("key", "ball", "door"):
                objects.append(MazeObject(t, entry.color, cell, entry.locked, entry.open))
    for what, found in (("agent starts 'A'", agents), ("goals", goals)):     # a legend goal is not drawn 'G'
        if len(found) != 1:
            at = " and ".join(f"line {rows[y][0]}, column {x + 1} ({rows[y][1][x]!r}, cell [{x}, {y}])"
                              for x, y in found)
            raise SpecError(f"{source}: found {len(found)} {what}{' at ' + at if at else ''}; draw exactly one")
    return Layout(width, height, frozenset(walls), frozenset(lava), agents[0], goals[0],
                  tuple(objects), tuple(r for _, r in rows))


def _err(source: str, key: str, msg: str) -> SpecError:
    return SpecError(f"{source}: {key}: {msg}")


class _AtArgs(StrictModel):
    cell: tuple[int, int]


class _CarryingArgs(StrictModel):
    type: Literal["key", "ball"] = "key"
    color: str


class _DoorOpenArgs(StrictModel):
    color: str | None = None
    cell: tuple[int, int] | None = None

    @model_validator(mode="after")
    def _one(self) -> _DoorOpenArgs:
        if (self.color is None) == (self.cell is None):
            raise ValueError("give exactly one of color or cell")
        return self


class _GoalArgs(StrictModel):
    pass


_ARGS: dict[str, type[BaseModel]] = {"at": _AtArgs, "carrying": _CarryingArgs,
                                     "door_open": _DoorOpenArgs, "goal": _GoalArgs}


def _compile_predicate(i: int, sg: Any, lay: Layout, carry_kinds: tuple[tuple[str, str], ...],
                       source: str, layout_name: str) -> Predicate:
    key = f"subgoals[{i}] ({sg.name})"
    if sg.kind not in _ARGS:
        raise _err(source, f"{key}.kind", f"unknown predicate kind {sg.kind!r}; the minigrid family "
                   f"knows: {', '.join(PREDICATE_KINDS)}")
    try:
        args = _ARGS[sg.kind].model_validate(sg.args)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err, prefix=f"{key}.args")) from None

    def inside(cell: tuple[int, int], what: str) -> None:
        x, y = cell
        if not (0 <= x < lay.width and 0 <= y < lay.height):
            raise _err(source, f"{key}.args.cell", f"{list(cell)} is outside the {lay.width}x{lay.height} "
                       f"grid of {layout_name}; use 0 <= x < {lay.width}, 0 <= y < {lay.height}")
        if cell in lay.walls:
            raise _err(source, f"{key}.args.cell", f"{list(cell)} is a wall in {layout_name}; pick a "
                       f"{what} cell")

    if sg.kind == "at":
        inside(args.cell, "floor")
        return Predicate(sg.name, "at", tuple(args.cell))
    if sg.kind == "goal":
        return Predicate(sg.name, "goal", lay.goal)
    if sg.kind == "carrying":
        matches = [o for o in lay.carriables if (o.type, o.color) == (args.type, args.color)]
        if not matches:
            have = sorted({f"{c} {t}" for t, c in carry_kinds}) or ["none"]
            raise _err(source, f"{key}.args", f"no {args.color} {args.type} in {layout_name} (it has: "
                       f"{', '.join(have)}); fix the colour or add one to the layout")
        if len(matches) > 1:
            raise _err(source, f"{key}.args", f"{len(matches)} {args.color} {args.type}s in "
                       f"{layout_name}; the low-level target would be ambiguous, keep one")
        return Predicate(sg.name, "carrying", matches[0].cell, carry_kinds.index((args.type, args.color)))
    doors = lay.doors
    if args.cell is not None:
        inside(args.cell, "door")
        idx = [j for j, d in enumerate(doors) if d.cell == tuple(args.cell)]
        if not idx:
            raise _err(source, f"{key}.args.cell", f"no door at {list(args.cell)} in {layout_name}; doors "
                       f"are at {[list(d.cell) for d in doors] or 'nowhere'}")
    else:
        idx = [j for j, d in enumerate(doors) if d.color == args.color]
        if not idx:
            have = sorted({d.color for d in doors}) or ["none"]
            raise _err(source, f"{key}.args.color", f"no {args.color} door in {layout_name} (door colours: "
                       f"{', '.join(have)}); fix the colour or add the door to the layout")
        if len(idx) > 1:
            raise _err(source, f"{key}.args.color", f"{len(idx)} {args.color} doors in {layout_name}; "
                       f"name the door by cell instead")
    return Predicate(sg.name, "door_open", doors[idx[0]].cell, idx[0])


class _OptionsHolder(StrictModel):
    options: MazeOptions


def _build(cat: Catalogue) -> MazeSpec:
    source = cat.source
    if cat.family != "minigrid":
        raise _err(source, "family", f"{cat.family!r} is not a minigrid task; use family: minigrid")
    if isinstance(cat.options, dict) and "gym_id" in cat.options:
        raise _err(source, "options.gym_id", "a registered MiniGrid environment is generated again at every reset, so "
                   "it has no fixed layout to read or search; build it with envs.make (RegisteredEnv)")
    try:
        opts = _OptionsHolder.model_validate({"options": cat.options}).options
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err)) from None
    path = cat.resolve(opts.layout)
    if not path.is_file():
        raise _err(source, "options.layout", f"layout file {str(path)!r} " + ("is a directory" if path.is_dir()
                   else "not found") + "; give the path of a layout file relative to the catalogue's folder")
    try:
        text = path.read_text(encoding="utf-8-sig")   # a BOM (Windows editors) is not a cell
    except UnicodeDecodeError as exc:
        raise SpecError(f"{path}: not UTF-8 text (byte {exc.start}); save the layout as UTF-8") from None
    lay = parse_layout(text, opts.legend, source=str(path))
    carry_kinds = tuple(dict.fromkeys((o.type, o.color) for o in lay.carriables))
    preds = tuple(_compile_predicate(i, sg, lay, carry_kinds, source, path.name)
                  for i, sg in enumerate(cat.subgoals))
    landmarks = preds if cat.observed is None else tuple(
        _compile_predicate(i, sg, lay, carry_kinds, source, path.name) for i, sg in enumerate(cat.observed))
    max_steps = opts.max_steps or 4 * lay.width * lay.height
    return MazeSpec(cat, opts, lay, preds, max_steps, carry_kinds, landmarks)


@functools.lru_cache(maxsize=64)
def _cached(path: str, mtime_ns: int, layout_mtime: int) -> MazeSpec:
    return _build(load_catalogue(path))


def load_maze_spec(catalogue: str | Path | Catalogue) -> MazeSpec:
    """Load and validate a minigrid task: catalogue, options, layout and sub-goal predicates.

    Specs from files are cached by (path, modification time), so building many envs parses once.
    """
    if isinstance(catalogue, Catalogue):
        return _build(catalogue)
    path = Path(catalogue)
    if not path.is_file():
        raise SpecError(f"{path}: no such catalogue file; check the path or use a built-in task name")
    cat = load_catalogue(path)
    layout_rel = cat.options.get("layout") if isinstance(cat.options, dict) else None
    lay_path = cat.resolve(layout_rel) if isinstance(layout_rel, str) else None
    lay_mtime = lay_path.stat().st_mtime_ns if lay_path is not None and lay_path.is_file() else 0
    return _cached(str(path.resolve()), path.stat().st_mtime_ns, lay_mtime)
