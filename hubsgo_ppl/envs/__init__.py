"""Tasks: MiniGrid mazes and robosuite arm tasks, each declared by a catalogue YAML in ``envs/``.

Registration is explicit (no import side effects, cf. MiniGrid #455)::

    import hubsgo_ppl.envs as tasks
    tasks.register()                       # registers every built-in task with Gymnasium, once
    env = tasks.make("keydoor", seed=0)    # or gymnasium.make("hubsgo/KeyDoor-v0")
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym

from ..resources import envs_dir
from ..specs import SpecError
from .subgoals import Catalogue, SubgoalDef, load_catalogue

__all__ = ["TaskInfo", "Catalogue", "SubgoalDef", "load_catalogue", "tasks", "get_task", "register",
           "make", "UnknownTaskError"]

# family -> entry point of the env class that takes (catalogue=..., **kwargs)
_FAMILY_ENTRY = {
    "minigrid": "hubsgo_ppl.envs.minigrid.registered:make_minigrid",     # a layout (MazeEnv) or a gym_id
    "robosuite": "hubsgo_ppl.envs.robosuite.gym_wrapper:make_robosuite_task",
    "gym": "hubsgo_ppl.envs.gym_task:GymTask",          # any Gymnasium env (envs/gym_task.py)
}


class UnknownTaskError(SpecError):
    """A task name that is neither built in nor a catalogue file."""


@dataclass(frozen=True)
class TaskInfo:
    name: str           # short name used by the CLI, e.g. "keydoor"
    env_id: str         # Gymnasium id, e.g. "hubsgo/KeyDoor-v0"
    family: str
    catalogue_path: Path

    @property
    def catalogue(self) -> Catalogue:
        return load_catalogue(self.catalogue_path)

    @property
    def shipped(self) -> bool:
        """Whether this is a built-in task's own catalogue (by name, or by the path of its file): only those
        take the task's settings (``agents/presets.py``); a user's catalogue of the same name takes its
        family's defaults, as every user catalogue does."""
        own = tasks().get(self.name)
        return own is not None and own.catalogue_path.resolve() == Path(self.catalogue_path).resolve()


def _env_id(cat: Catalogue) -> str:
    camel = cat.title or "".join(p.capitalize() for p in cat.task.replace("-", "_").split("_"))
    return f"hubsgo/{camel}-v0"


#: a Gymnasium environment id (``[namespace/]Name-vN``), as ``gymnasium.make`` takes it
_GYM_ID = re.compile(r"(?:[\w.-]+/)?[\w.:-]+-v\d+")

_CACHE: dict[tuple, dict[str, TaskInfo]] = {}


def tasks(directory: Path | None = None) -> dict[str, TaskInfo]:
    """Every task catalogue in ``directory`` (default: the built-in ``envs/``), by task name.

    Cached on the files' names and modification times, so edits to a catalogue are picked up.
    """
    directory = Path(directory) if directory else envs_dir()
    paths = sorted(directory.glob("*.yaml"))
    key = (str(directory), tuple((str(p), p.stat().st_mtime_ns) for p in paths))
    if key not in _CACHE:
        out: dict[str, TaskInfo] = {}
        for path in paths:
            cat = load_catalogue(path)
            if cat.task in out:
                raise SpecError(f"{path}: task: {cat.task!r} is also declared by {out[cat.task].catalogue_path}; "
                                "give each catalogue a unique `task` name")
            out[cat.task] = TaskInfo(cat.task, _env_id(cat), cat.family, path)
        _CACHE.clear()
        _CACHE[key] = out
    return dict(_CACHE[key])


def get_task(name_or_path: str | Path) -> TaskInfo:
    """A built-in task by name, or a user's catalogue by path."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml"):
        cat = load_catalogue(p)
        return TaskInfo(cat.task, _env_id(cat), cat.family, p)
    known = tasks()
    name = str(name_or_path)
    if name not in known:
        ours = next((info.name for info in known.values() if info.env_id == name), None)
        if ours is not None:
            raise UnknownTaskError(f"{name!r} is the Gymnasium id of task {ours!r}: pass {ours}")
        wraps = sorted(info.name for info in known.values()
                       if info.family == "minigrid" and load_catalogue(info.catalogue_path).options.get("gym_id") == name)
        if wraps:
            raise UnknownTaskError(
                f"{name!r} is a Gymnasium id, not a task; task {wraps[0]!r} wraps it with a catalogue of sub-goals: "
                f"pass {wraps[0]} (`hubsgo tasks` lists its sub-goals), or copy {known[wraps[0]].catalogue_path} and "
                "edit its sub-goals")
        if _GYM_ID.fullmatch(name) and not _known_id(name):
            raise UnknownTaskError(
                f"unknown task {name!r}, and no Gymnasium id of that name is registered; use one of: "
                f"{', '.join(sorted(known))} (`hubsgo tasks` lists them), or a path to a catalogue .yaml")
        if _GYM_ID.fullmatch(name):
            raise UnknownTaskError(
                f"{name!r} is a Gymnasium id, not a task: write a catalogue that names it and lists the sub-goals "
                "to learn (family minigrid with options.gym_id for MiniGrid's environments, docs/minigrid.md; "
                f"family gym for any other, docs/own_env.md), and pass the catalogue's path; `hubsgo check-env "
                f"{name}` prints a draft for a MiniGrid environment")
        raise UnknownTaskError(
            f"unknown task {name!r}; use one of: {', '.join(sorted(known))} "
            f"(`hubsgo tasks` lists them), or a path to a catalogue .yaml")
    return known[name]


def _known_id(env_id: str) -> bool:
    """Whether Gymnasium knows ``env_id`` (MiniGrid's ids registered first); a ``module:Id`` or a
    namespaced ``NS/Id`` is taken as known, the package that registers it importing on ``gym.make``
    or in the user's own code."""
    if ":" in env_id or "/" in env_id:
        return True
    try:
        import minigrid  # noqa: F401 - registers MiniGrid's and BabyAI's ids
    except ImportError:
        pass
    return env_id in gym.registry


_registered = False


def register() -> list[str]:
    """Register every built-in task with Gymnasium (idempotent). Returns the ids."""
    global _registered
    ids = []
    for info in tasks().values():
        if info.env_id not in gym.registry:
            gym.register(id=info.env_id, entry_point=_FAMILY_ENTRY[info.family],
                         kwargs={"catalogue": str(info.catalogue_path)})
        ids.append(info.env_id)
    _registered = True
    return ids


def make(name_or_path: str | Path, seed: int | None = None, **kwargs: Any) -> gym.Env:
    """Build a task env (unwrapped-compatible Gymnasium env); reset it with ``seed`` if given."""
    info = get_task(name_or_path)
    module, cls = _FAMILY_ENTRY[info.family].split(":")
    factory = getattr(__import__(module, fromlist=[cls]), cls)
    env = factory(catalogue=str(info.catalogue_path), **kwargs)
    if seed is not None:
        env.reset(seed=seed)
    return env
