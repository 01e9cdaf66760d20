"""Sub-goal catalogues: the named candidate sub-goals G0 of a task, declared in YAML under ``envs/``.

A catalogue is shared by every task family. Each sub-goal has a ``kind`` (an achievement predicate
known to the family, e.g. MiniGrid ``at``/``carrying``/``door_open``/``goal``, robosuite
``reach_above``/``grasp``/``place_on``/...) with its ``args``; the family turns it into an achievement
test and a target for the low level.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, field_validator

from ..specs import SpecError, StrictModel, load_yaml, validate_spec

__all__ = ["SubgoalDef", "Catalogue", "load_catalogue", "file_in_folder"]


class SubgoalDef(StrictModel):
    """One candidate sub-goal: a named predicate with arguments."""

    name: str = Field(description="unique name, e.g. 'yellow_key'")
    kind: str = Field(description="predicate kind understood by the task family")
    args: dict[str, Any] = Field(default_factory=dict, description="arguments of the predicate")
    description: str = ""

    @field_validator("name")
    @classmethod
    def _name_ok(cls, v: str) -> str:
        if not v or not v.replace("_", "").replace("-", "").isalnum():
            raise ValueError(f"sub-goal name {v!r} must be letters, digits, '_' or '-'")
        return v


class Catalogue(StrictModel):
    """A task: its family, family-specific options, and its sub-goal catalogue (G0)."""

    task: str = Field(description="short name used on the command line, e.g. 'keydoor'")
    title: str = Field(default="", description="CamelCase name for the Gymnasium id, e.g. 'KeyDoor'")
    family: Literal["minigrid", "robosuite", "gym"]
    description: str = ""
    options: dict[str, Any] = Field(default_factory=dict)
    subgoals: list[SubgoalDef]
    source: str = Field(default="<catalogue>", exclude=True)
    # the whole catalogue's sub-goals when this one is a subset of it (``envs.subset``); an egocentric
    # maze observation measures its offsets to these, so dropping sub-goals leaves its shape alone
    observed: list[SubgoalDef] | None = Field(default=None, exclude=True)

    @field_validator("task")
    @classmethod
    def _task_ok(cls, v: str) -> str:
        if not v or not v.replace("_", "").replace("-", "").isalnum() or not v.isascii():
            raise ValueError(f"task name {v!r} must be letters, digits, '_' or '-' (it is typed on the command line)")
        return v

    @field_validator("title")
    @classmethod
    def _title_ok(cls, v: str) -> str:
        if v and not (v.replace("_", "").replace("-", "").replace(".", "").isalnum() and v.isascii()):
            camel = "".join(w[:1].upper() + w[1:] for w in re.split(r"[^A-Za-z0-9]+", v)) or "MyMaze"
            raise ValueError(f"title {v!r} names the Gymnasium id hubsgo/TITLE-v0, so it must be letters, digits, "
                             f"'_', '-' or '.'; e.g. {camel!r}")
        return v

    @field_validator("subgoals")
    @classmethod
    def _unique(cls, v: list[SubgoalDef]) -> list[SubgoalDef]:
        if not v:
            raise ValueError("a task needs at least one sub-goal")
        seen: set[str] = set()
        for sg in v:
            if sg.name in seen:
                raise ValueError(f"duplicate sub-goal name {sg.name!r}; names must be unique")
            seen.add(sg.name)
        return v

    @property
    def names(self) -> list[str]:
        return [sg.name for sg in self.subgoals]

    def resolve(self, relative: str, key: str = "options.layout") -> Path:
        """A file named in ``options`` at ``key`` (e.g. a layout), in the catalogue's folder
        (:func:`file_in_folder`)."""
        return file_in_folder(self.source, relative, key)


def file_in_folder(source: str | Path, relative: str, key: str) -> Path:
    """The file ``relative`` names, relative to the folder of the catalogue ``source``.

    Only that folder (and the folders below it) is read: an absolute path, or one that leads out of it
    through ``..`` or a symbolic link, is a SpecError naming the catalogue and the key."""
    folder = Path(source).parent
    if Path(relative).is_absolute():
        raise SpecError(f"{source}: {key}: {relative!r} is an absolute path; name a file in the catalogue's "
                        "folder, relative to it")
    path = folder / relative
    try:
        inside = path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError):         # a loop of symbolic links
        inside = False
    if not inside:
        raise SpecError(f"{source}: {key}: {relative!r} leads out of the catalogue's folder; put the file in "
                        "that folder (not a link to elsewhere) and name it relative to it")
    return path


def load_catalogue(path: str | Path) -> Catalogue:
    """Load and validate a task catalogue YAML; errors name the file and key."""
    if Path(path).is_dir():
        raise SpecError(f"{path}: a directory, not a task catalogue file; pass the path of a catalogue's YAML file, "
                        "or a built-in task name (`hubsgo tasks` lists them)")
    if not Path(path).is_file():
        where = "" if Path(path).is_absolute() else f" (relative to {Path.cwd()})"
        raise SpecError(f"{path}: no such task catalogue file{where}; check the path, or pass a built-in task "
                        "name (`hubsgo tasks` lists them)")
    data = load_yaml(path)
    cat = validate_spec(Catalogue, data, source=str(path))
    cat.source = str(path)
    return cat


