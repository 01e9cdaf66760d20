"""Declarative specs: YAML files -> validated, typed objects.

Every spec error is a :class:`SpecError` whose message names the file, the key and a fix, e.g.::

    models/keydoor.yaml: edges[2]: 'blue_dor' is not a sub-goal; use one of: yellow_key, ...

Specs are strict (unknown keys are errors), following Pyro's habit of rejecting unrecognised options.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError

__all__ = ["SpecError", "StrictModel", "load_yaml", "validate_spec", "format_validation_error"]

M = TypeVar("M", bound=BaseModel)


class SpecError(ValueError):
    """A spec (model, task catalogue, sweep) is malformed. The message says where and how to fix it."""


class StrictModel(BaseModel):
    """Base for spec objects: unknown keys are rejected, values are validated on assignment."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)


def _loc(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "<top level>"


def format_validation_error(source: str, err: ValidationError) -> str:
    """Turn pydantic's error list into one line per problem: ``file: key: problem; fix``."""
    lines = []
    for e in err.errors():
        loc = tuple(p for p in e["loc"] if not (isinstance(p, str) and p.startswith("function-")))
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key; remove it or check its spelling"
        elif e["type"] == "missing":
            msg = "required key is missing; add it"
        lines.append(f"{source}: {_loc(loc)}: {msg}")
    return "\n".join(lines)


def load_yaml(path: str | Path) -> dict[str, Any]:
    """Read a YAML mapping, with errors that name the file."""
    path = Path(path)
    if not path.is_file():
        raise SpecError(f"{path}: no such spec file; check the path or use a built-in name")
    try:
        data = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        raise SpecError(f"{path}: not valid YAML ({exc}); fix the syntax") from None
    if not isinstance(data, dict):
        raise SpecError(f"{path}: <top level>: expected a mapping of keys, got {type(data).__name__}")
    return data


def validate_spec(cls: type[M], data: dict[str, Any], source: str = "<spec>") -> M:
    """Validate ``data`` into ``cls``; raise :class:`SpecError` naming ``source`` and each bad key."""
    try:
        return cls.model_validate(data)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err)) from None
