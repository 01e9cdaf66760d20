"""RegisteredEnv: a MiniGrid environment registered with Gymnasium, with a catalogue's sub-goals.

A minigrid catalogue names either an ASCII ``layout`` (:class:`~hubsgo_ppl.envs.minigrid.maze.MazeEnv`)
or a registered MiniGrid id::

    task: keycorridor
    family: minigrid
    options:
      gym_id: MiniGrid-KeyCorridorS3R3-v0    # any id whose env is a MiniGridEnv (BabyAI's included)
      actions: [left, right, forward, pickup, drop, toggle]
      max_steps: 270                         # default: the environment's own
      obs_mode: egocentric                   # egocentric (default) | image
    subgoals:
      - {name: key, kind: carrying, args: {type: key}}
      - {name: door, kind: door_open, args: {locked: true}}
      - {name: goal, kind: goal}

The layout is the environment's own, generated again at every reset from the seeded reset; the
sub-goal kinds of :mod:`.kinds` read the live grid, so nothing assumes a fixed layout. The rewards,
termination and truncation are the environment's; ``info["is_success"]`` is a positive reward on
termination (MiniGrid's ``1 - 0.9 * step_count / max_steps``).

Observation (``obs_mode: egocentric``, the default, as :mod:`.egocentric` lays it out)::

    [carrying anything (1) | achieved (L) | offset (2L) | window (2 * 7 * 7)]

the offsets to each sub-goal's target in the agent's frame over ``max(W, H)``; the window's channel
0 is 1 where the agent cannot step (a wall, a closed door, an object on the floor, outside the grid),
channel 1 on lava. ``obs_mode: image`` is MiniGrid's full-grid encoding, ``W*H*3`` floats.
"""

from __future__ import annotations

import ast
import contextlib
import inspect
import io
import sys
import textwrap
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from minigrid.core.actions import Actions
from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX
from pydantic import Field, ValidationError, field_validator

from ...specs import SpecError, StrictModel, format_validation_error
from ..subgoals import Catalogue, load_catalogue
from . import egocentric, image
from .kinds import KINDS, Kind, Scene, mission_named, compile_kind, new_scene
from .reach import at_cells, goal_reachable, is_wall, missing_for_goal

__all__ = ["RegisteredOptions", "RegisteredEnv", "is_registered", "make_minigrid"]


class RegisteredOptions(StrictModel):
    """The ``options`` of a minigrid catalogue that names a registered environment."""

    gym_id: str = Field(description="a registered Gymnasium id whose env is a MiniGridEnv")
    max_steps: int | None = Field(default=None, gt=0, description="truncation; default the environment's own")
    actions: list[str] = Field(default_factory=lambda: ["left", "right", "forward", "pickup", "toggle"])
    obs_mode: Literal["egocentric", "image"] = "egocentric"

    @field_validator("actions")
    @classmethod
    def _actions_ok(cls, v: list[str]) -> list[str]:
        known = [a.name for a in Actions]
        bad = [a for a in v if a not in known]
        if bad:
            raise ValueError(f"unknown action(s) {bad}; use names from: {', '.join(known)}")
        if not v or len(set(v)) != len(v):
            raise ValueError("actions must be a non-empty list without repeats")
        return v


def is_registered(catalogue: Catalogue | str | Path) -> bool:
    """Whether a minigrid catalogue names a registered environment (``options.gym_id``)."""
    cat = catalogue if isinstance(catalogue, Catalogue) else load_catalogue(catalogue)
    return cat.family == "minigrid" and isinstance(cat.options, dict) and "gym_id" in cat.options


def _inner(gym_id: str, source: str, **kwargs: Any) -> Any:
    import minigrid  # noqa: F401  (registers MiniGrid's and BabyAI's ids)
    from minigrid.minigrid_env import MiniGridEnv

    if gym_id not in gym.registry:
        near = sorted(k for k in gym.registry if k.lower().startswith(gym_id.split("-v")[0].lower()[:12]))[:3]
        hint = f" (similar: {', '.join(near)})" if near else ""
        raise SpecError(f"{source}: options.gym_id: {gym_id!r} is not a registered Gymnasium id{hint}; use a "
                        "MiniGrid id such as MiniGrid-DoorKey-8x8-v0")
    try:
        env = gym.make(gym_id, disable_env_checker=True, **kwargs).unwrapped
    except TypeError as exc:
        raise SpecError(f"{source}: options: {gym_id} does not take {exc}; drop that option") from None
    except Exception as exc:                # a non-MiniGrid id may need packages or arguments we lack
        raise SpecError(f"{source}: options.gym_id: {gym_id!r} could not be built ({type(exc).__name__}: {exc}); "
                        "use a MiniGrid id") from None
    if not isinstance(env, MiniGridEnv):
        env.close()
        raise SpecError(f"{source}: options.gym_id: {gym_id!r} is not a MiniGrid environment ({type(env).__name__}); "
                        "name a MiniGrid id, or write an ASCII layout (options.layout)")
    return env


PROBE_RESETS = 8


def _quiet_reset(env: Any, seed: int | None, options: dict[str, Any] | None = None) -> None:
    """``env.reset``, with what MiniGrid's generators print (BabyAI's rejected samples) kept off stdout."""
    with contextlib.redirect_stdout(io.StringIO()):
        env.reset(seed=seed, options=options)


def _probe(gym_id: str, source: str, kwargs: dict[str, Any], kinds: tuple[Kind, ...], actions: list[str],
           goal_pays: bool, cells: list[tuple[int, Any]] = ()) -> list[str] | None:
    """Refuse, in one line, an env that cannot generate a layout, and a sub-goal whose type of object is in
    none of ``PROBE_RESETS`` seeded layouts (on the floor, in a box or carried at reset); warn, once, where
    the type is there but never in the colour (or lock) the sub-goal names, as environments that draw
    colours at random may have it in other layouts, and where an ``at`` cell (``cells``) is a wall in all.

    Where the goal square pays (``goal_pays``) and ``actions`` reach it (:mod:`.reach`) in none of the
    layouts that have one (DoorKey without ``toggle``), returns what :func:`_check_actions` refuses: the
    actions that would reach it (empty where none would); else None. The caller's env is untouched."""
    wanted = [(i, k, what, match) for i, k in enumerate(kinds) for what, match in k.selects]
    env, seen = _inner(gym_id, source, **kwargs), set()
    # what the first layout whose goal square is out of reach would need; None while there is none
    missing: list[str] | None = None
    try:
        for seed in range(PROBE_RESETS):
            try:
                _quiet_reset(env, seed)
            except Exception as exc:        # e.g. a generator whose optional dependencies are missing
                raise SpecError(f"{source}: options.gym_id: {gym_id!r} could not generate a layout "
                                f"({type(exc).__name__}: {' '.join(str(exc).split())}); use a MiniGrid id "
                                "whose dependencies are installed") from None
            if goal_pays:
                reached = goal_reachable(env, actions)      # None: a layout with no goal square
                if reached is False and missing is None:
                    missing = missing_for_goal(env, actions)
                elif reached or missing is None:
                    goal_pays = False       # settled: a goal square in reach, or layouts without one
            cells = [(i, c) for i, c in cells if is_wall(env, c)]     # those a wall in every layout so far
            if not wanted and not goal_pays and not cells:
                return None
            s = new_scene(env.grid, tuple(env.agent_pos), env.carrying)
            objs = [o for o, _ in s.objects] + [o.contains for o, _ in s.objects
                                                if o.type == "box" and o.contains is not None]
            objs += [env.carrying] if env.carrying is not None else []
            seen |= {f"{o.color} {o.type}" for o in objs}
            wanted = [(i, k, what, m) for i, k, what, m in wanted if not any(m(s, o) for o in objs)]
    finally:
        env.close()
    blocked = missing if goal_pays else None
    for i, c in cells:
        _warn(f"{source}: subgoals[{i}] ({kinds[i].name}).args.cell: {list(c)} is a wall in all {PROBE_RESETS} "
              f"seeded layouts of {gym_id}, so the agent cannot stand on it there; pick a floor cell")
    if not wanted:
        return blocked
    types = {entry.split()[-1] for entry in seen}
    for i, k, what, _ in wanted:
        article = "an" if what[0] in "aeiou" else "a"
        line = (f"{source}: subgoals[{i}] ({k.name}).args: {k.kind} needs {article} {what}, and {gym_id} has none "
                f"in {PROBE_RESETS} seeded layouts (it has: {', '.join(sorted(seen)) or 'walls only'})")
        named = what.split(" (")[0].split()[-1]
        if named in types or (named == "object" and types):
            # the type is there, only its colour or lock differs: layouts drawn at random may still have it
            _warn(f"{line}; it holds only in layouts that have one")
            continue
        raise SpecError(f"{line}; change its args or drop it")
    return blocked


#: the probe's warnings already printed in this process (an env is built for each run, evaluation, seed)
_WARNED: set[str] = set()


def _warn(line: str) -> None:
    if line not in _WARNED and not _WARNED.add(line):       # once per process
        print(f"hubsgo: warning: {line}", file=sys.stderr)


#: the MiniGrid actions a sub-goal kind cannot hold without (``forward`` is needed by every environment)
NEEDS: dict[str, tuple[str, ...]] = {"carrying": ("pickup",), "cleared": ("pickup",), "door_open": ("toggle",),
                                     "box_open": ("toggle",), "placed_near": ("pickup", "drop")}


def rewarded_actions(env_class: type) -> list[str]:
    """The actions whose branch of the environment's own ``step`` pays its reward: each ``if`` that tests
    ``action == self.actions.NAME`` and calls ``self._reward()`` inside (MiniGrid's Unlock: ``toggle``;
    UnlockPickup and KeyCorridor: ``pickup``; GoToDoor: ``done``, not the ``toggle`` that only ends its
    episode). Empty where the class keeps MiniGrid's ``step`` (the goal square pays) or has no source."""
    if "step" not in vars(env_class):
        return []
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(env_class.step)))
    except (OSError, TypeError, SyntaxError):       # no source to read (a compiled or dynamically built class)
        return []

    def tested(test: ast.expr) -> list[str]:
        return [n.attr for n in ast.walk(test) if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Attribute)
                and n.value.attr == "actions" and n.attr in Actions.__members__]

    def pays(body: list[ast.stmt]) -> bool:
        return any(isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute) and n.func.attr == "_reward"
                   for stmt in body for n in ast.walk(stmt))

    found = [name for node in ast.walk(tree) if isinstance(node, ast.If) and pays(node.body)
             for name in tested(node.test)]
    return list(dict.fromkeys(found))


def _check_actions(paid: list[str], actions: list[str], kinds: tuple[Kind, ...], gym_id: str, source: str,
                   blocked: list[str] | None = None) -> None:
    """Refuse, in one line, an action set that cannot reach a sub-goal or the environment's success: no
    ``forward``; a kind's action (``NEEDS``) missing; an action the environment's own ``step`` rewards
    missing (``paid``, :func:`rewarded_actions`: Unlock pays on ``toggle``, GoToDoor on ``done``); or,
    ``blocked`` (:func:`_probe`), no probed layout whose goal square the actions reach."""
    have = set(actions)
    needed = [("forward", "the agent could not move")] + [
        (a, f"subgoals[{i}] ({k.name}) is a {k.kind} sub-goal") for i, k in enumerate(kinds) for a in NEEDS.get(k.kind, ())]
    needed += [(a, f"{gym_id} rewards the {a} action") for a in paid]
    for action, why in needed:
        if action not in have:
            raise SpecError(f"{source}: options.actions: {action!r} is missing and {why}; add {action} to "
                            f"options.actions (now {actions})")
    if blocked is not None:
        hint = (f"add {' and '.join(blocked)} to options.actions (doors, keys or objects stand between the agent "
                "and the goal)" if blocked else "walls or lava cut the agent off from the goal in every one")
        raise SpecError(f"{source}: options.actions: with {actions} the agent can reach the goal square in none of "
                        f"{PROBE_RESETS} seeded layouts of {gym_id}; {hint}")


class RegisteredEnv(gym.Env):
    """A registered MiniGrid environment with a catalogue's sub-goals (see the module docstring).

    Args:
        catalogue: path to the catalogue YAML (or a loaded :class:`Catalogue`).
        obs_mode: ``"egocentric"`` or ``"image"``; overrides ``options.obs_mode``.
        max_steps: overrides ``options.max_steps``.
        render_mode: ``None`` or ``"rgb_array"`` (MiniGrid's renderer).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, catalogue: str | Path | Catalogue, obs_mode: str | None = None,
                 max_steps: int | None = None, render_mode: str | None = None, **kwargs: Any):
        cat = catalogue if isinstance(catalogue, Catalogue) else load_catalogue(catalogue)
        source = cat.source
        try:
            opts = RegisteredOptions.model_validate(cat.options)
        except ValidationError as err:
            raise SpecError(format_validation_error(source, err, prefix="options")) from None
        if obs_mode is not None and obs_mode not in ("egocentric", "image"):
            raise SpecError(f"{source}: obs_mode={obs_mode!r} is not supported on a registered MiniGrid environment, "
                            "whose layout changes at every reset; use 'egocentric' or 'image'")
        if kwargs:
            raise SpecError(f"{source}: {', '.join(sorted(kwargs))}: not an option of a registered MiniGrid "
                            "environment (it takes obs_mode, max_steps, render_mode)")
        steps = max_steps or opts.max_steps
        self.inner = _inner(opts.gym_id, source, render_mode=render_mode,
                            **({"max_steps": steps} if steps else {}))
        inner = self.inner
        # MiniGrid's own partial view is never observed here; skipping it makes a step several times cheaper
        inner.gen_obs = lambda: {"image": None, "direction": inner.agent_dir, "mission": inner.mission}
        self.catalogue, self.gym_id, self.render_mode = cat, opts.gym_id, render_mode
        self.obs_mode = obs_mode or opts.obs_mode
        self.subgoal_names: list[str] = cat.names
        self._kinds: tuple[Kind, ...] = tuple(compile_kind(i, sg, source) for i, sg in enumerate(cat.subgoals))
        marks = cat.observed or cat.subgoals
        self._marks: tuple[Kind, ...] = self._kinds if cat.observed is None else tuple(
            compile_kind(i, sg, source) for i, sg in enumerate(marks))
        self._mark_cols = np.array([[sg.name for sg in marks].index(n) for n in self.subgoal_names], np.int64)
        paid = rewarded_actions(type(self.inner))     # actions the env's own step pays on (none: the goal square)
        W, H = self.inner.width, self.inner.height
        cells = at_cells(cat.subgoals, W, H, opts.gym_id, source)       # refuses a cell outside the grid
        blocked = _probe(opts.gym_id, source, {"max_steps": steps} if steps else {}, self._kinds, opts.actions,
                         goal_pays=not paid, cells=cells)
        _check_actions(paid, opts.actions, self._kinds, opts.gym_id, source, blocked)
        self._action_map = tuple(Actions[a] for a in opts.actions)
        self.action_names = list(opts.actions)
        self.action_space = spaces.Discrete(len(self._action_map))
        if self.obs_mode == "egocentric":
            self.observation_space = spaces.Box(-1.0, 1.0, (egocentric.dim(len(marks)),), np.float32)
        else:
            self.observation_space = spaces.Box(0.0, 255.0, (W * H * 3,), np.float32)
        self.scene: Scene | None = None

    # -- what MiniGrid's tools read (the renderer, the recorder) -----------------------------------

    @property
    def width(self) -> int:
        return self.inner.width

    @property
    def height(self) -> int:
        return self.inner.height

    @property
    def grid(self) -> Any:
        return self.inner.grid

    @property
    def agent_pos(self) -> Any:
        return self.inner.agent_pos

    @property
    def agent_dir(self) -> int:
        return self.inner.agent_dir

    @property
    def carrying(self) -> Any:
        return self.inner.carrying

    @property
    def max_steps(self) -> int:
        return self.inner.max_steps

    @property
    def mission(self) -> str:
        return self.inner.mission

    def get_frame(self, *args: Any, **kwargs: Any) -> np.ndarray:
        return self.inner.get_frame(*args, **kwargs)

    def render(self) -> Any:
        return self.inner.render()

    def close(self) -> None:
        self.inner.close()

    # -- the scene the kinds read ------------------------------------------------------------------

    def _agent_cell(self) -> tuple[int, int]:
        x, y = self.inner.agent_pos
        return int(x), int(y)

    def _front(self) -> tuple[int, int]:
        x, y = self.inner.front_pos
        return int(x), int(y)

    def _rescan(self) -> None:
        """Re-read the objects and the window's map: channel 0, where the agent cannot step (a wall, a
        closed door, an object on the floor, outside the grid); channel 1, lava."""
        s = self.scene
        pad = egocentric.VIEW // 2
        if s.version == 0:          # just reset: walls and lava, once per episode
            W, H = s.walls.shape
            base = np.zeros((2, W + 2 * pad, H + 2 * pad), np.float32)
            base[0] = 1.0
            base[0, pad:pad + W, pad:pad + H] = s.walls
            base[1, pad:pad + W, pad:pad + H] = s.lava
            self._base = base
        s.reread(self.inner.grid, self.inner.carrying)
        grid = self._base.copy()
        for obj, (x, y) in s.objects:
            if obj.type not in ("goal", "floor", "lava") and not (obj.type == "door" and obj.is_open):
                grid[0, x + pad, y + pad] = 1.0
        self._window = grid

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        _quiet_reset(self.inner, seed, options)
        self.scene = new_scene(self.inner.grid, self._agent_cell(), self.inner.carrying,
                               getattr(self.inner, "obj", None), getattr(self.inner, "target_pos", None),
                               self.inner.mission, self._front())
        self._rescan()
        return self._obs(), {"subgoals": self.subgoal_achieved(), "is_success": False}

    def step(self, action):
        a = int(action)
        if not 0 <= a < len(self._action_map):
            raise ValueError(f"action {action!r} is outside Discrete({len(self._action_map)}); "
                             f"actions are {self.action_names}")
        act = self._action_map[a]
        _, reward, terminated, truncated, _ = self.inner.step(act)
        s = self.scene
        s.agent, s.front = self._agent_cell(), self._front()
        self._rescan()          # every step: some environments move their objects themselves (DynamicObstacles)
        s.success = bool(terminated) and reward > 0
        return (self._obs(), float(reward), bool(terminated), bool(truncated),
                {"subgoals": self.subgoal_achieved(), "is_success": s.success})

    # -- sub-goal contract (docs/design.md) -------------------------------------------------------

    def subgoal_achieved(self) -> np.ndarray:
        """Which catalogue sub-goals hold now: bool array (N,)."""
        return self._held[self._mark_cols]

    def subgoal_target(self, i: int) -> tuple[int, int]:
        """The cell the low level should reach or face for sub-goal ``i``, read from the live grid."""
        if not 0 <= int(i) < len(self._kinds):
            raise IndexError(f"sub-goal index {i} out of range; this task has {len(self._kinds)}: "
                             f"{self.subgoal_names}")
        return tuple(int(c) for c in self._kinds[int(i)].target(self.scene))

    def subgoal_potential(self):
        """phi(obs) -> (B, N): minus the Manhattan distance to each sub-goal's target over (W + H), read
        from the egocentric offsets, or from an image observation (:func:`.image.scene_potential`)."""
        if self.obs_mode == "image":
            mission = getattr(self.inner, "mission", None)
            named = mission_named(mission) if isinstance(mission, str) else None
            return image.scene_potential(self.width, self.height,
                                         [(k.kind, KINDS[k.kind].model_validate(sg.args))
                                          for k, sg in zip(self._kinds, self.catalogue.subgoals)],
                                         mission_type=named[1] if named else None)
        import torch

        n = len(self._marks)
        cols = torch.tensor([1 + n + 2 * j for j in self._mark_cols])
        scale = float(max(self.width, self.height)) / float(self.width + self.height)

        def phi(obs: torch.Tensor) -> torch.Tensor:
            return -(obs[..., cols].abs() + obs[..., cols + 1].abs()) * scale

        return phi

    def _obs(self) -> np.ndarray:
        """The observation; also reads which landmarks hold (``_held``), once per step."""
        self._held = np.fromiter((k.holds(self.scene) for k in self._marks), bool, len(self._marks))
        if self.obs_mode == "image":
            img = self.inner.grid.encode()
            x, y = self._agent_cell()
            img[x, y] = (OBJECT_TO_IDX["agent"], COLOR_TO_IDX["red"], self.inner.agent_dir)
            return img.reshape(-1).astype(np.float32)
        s, marks = self.scene, self._marks
        return egocentric.compose(self.observation_space.shape[0], s.carrying is not None, self._held, s.agent,
                                  self.inner.agent_dir, [k.target(s) for k in marks],
                                  float(max(self.width, self.height)), self._window)


def make_minigrid(catalogue: str | Path | Catalogue, **kwargs: Any) -> gym.Env:
    """The env of a minigrid catalogue: a :class:`MazeEnv` for an ASCII ``layout``, a
    :class:`RegisteredEnv` for a ``gym_id``; both at once, or neither, is refused in one line."""
    cat = catalogue if isinstance(catalogue, Catalogue) else (
        load_catalogue(catalogue) if Path(catalogue).is_file() else None)
    opts = cat.options if cat is not None and isinstance(cat.options, dict) else {}
    if "gym_id" in opts:
        if "layout" in opts:
            raise SpecError(f"{cat.source}: options: give either layout (an ASCII maze) or gym_id (a registered "
                            "MiniGrid environment), not both")
        return RegisteredEnv(cat, **kwargs)
    if cat is not None and "layout" not in opts:
        other = f"; {', '.join(map(str, opts))}: not an option here" if opts else ""
        raise SpecError(f"{cat.source}: options: name the environment, by gym_id (a registered MiniGrid id such as "
                        f"MiniGrid-DoorKey-8x8-v0) or by layout (an ASCII maze){other}")
    from .maze import MazeEnv

    return MazeEnv(catalogue, **kwargs)
