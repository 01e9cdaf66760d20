"""The one formatter of pydantic's validation errors: each problem as one line naming where it is.

It needs pydantic only and imports nothing of the package, so that every layer can use it (the
critic's settings in ``infer`` as well as the specs above them). :mod:`hubsgo_ppl.specs` re-exports
it as ``format_validation_error``, the name the rest of the package uses.

Two styles, by what the values came from:

* a file (the default): ``models/x.yaml: edges[2]: 'blue_dor' is not in subgoals; ...``, and
  ``models/x.yaml: sigma: unknown key; remove it or check its spelling``;
* keyword settings (``model=`` given): ``InferenceConfig.lr = -1.0: input should be greater than 0
  (default 0.05)``, and ``InferenceConfig.burnin: unknown setting; use one of: lr, burn_in, ...``.

What a file gave is shown shortened (keys to 40 characters, values to 60), the unknown keys under
one key are named in one line (five of them, then how many more), and at most ``limit`` problems
are listed, so that an error never prints a file back at length.
"""

from __future__ import annotations

import typing
from typing import Any

from pydantic import BaseModel, ValidationError
from pydantic_core import PydanticUndefined

__all__ = ["format_validation_error", "no_bool_as_number", "shorten", "KEY_CHARS", "VALUE_CHARS", "PROBLEMS_SHOWN",
           "KEYS_SHOWN"]

#: the longest key, and value, an error message shows (longer ones are cut, with "...")
KEY_CHARS, VALUE_CHARS = 40, 60
#: the problems listed by default, and the unknown keys named in one; more are counted ("and 3 more")
PROBLEMS_SHOWN, KEYS_SHOWN = 8, 5


def shorten(text: str, chars: int) -> str:
    """``text`` on one line, cut to ``chars`` characters (ending in "...") where it is longer."""
    text = " ".join(str(text).split())
    return text if len(text) <= chars else text[:max(chars - 3, 1)] + "..."


def _where(loc: tuple[Any, ...]) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{shorten(part, KEY_CHARS)}" if out
                                                          else shorten(part, KEY_CHARS))
    return out


def _default(model: type[BaseModel], loc: tuple[Any, ...]) -> str:
    field = model.model_fields.get(loc[0]) if len(loc) == 1 else None
    if field is None or field.default is PydanticUndefined:
        return ""
    return f" (default {field.default!r})"


def format_validation_error(source: str, err: ValidationError, *, prefix: str = "", sep: str = "\n",
                            model: type[BaseModel] | None = None, limit: int = PROBLEMS_SHOWN) -> str:
    """pydantic's error list as one line per problem, joined by ``sep``.

    ``source`` names where the values came from: a file (``source: key: problem``), or with ``model``
    the settings class (``source.key = value: problem (default d)``, an unknown key listing
    ``model``'s fields). ``prefix`` is the key every location is under (e.g. ``subgoals[2] (door).args``
    for the arguments of one sub-goal). At most ``limit`` problems are listed, then how many more."""
    problems, unknown = [], {}          # in a file, the unknown keys under one key are said once
    for e in err.errors():
        loc = tuple(p for p in e["loc"] if not (isinstance(p, str) and p.startswith("function-")))
        if e["type"] == "extra_forbidden" and model is None and loc:
            parent = loc[:-1]
            if parent not in unknown:
                unknown[parent] = []
                problems.append({"type": "unknown_keys", "loc": parent, "keys": unknown[parent]})
            unknown[parent].append(shorten(loc[-1], KEY_CHARS))
        else:
            problems.append({**e, "loc": loc})
    lines = []
    for e in problems[:limit]:
        loc = e["loc"]
        where = ".".join(p for p in (prefix, _where(loc)) if p).replace(".[", "[")
        kind, msg = e["type"], e.get("msg", "")
        if kind == "unknown_keys":
            keys = e["keys"]
            if len(keys) == 1:
                where = ".".join(p for p in (where, keys[0]) if p)
                msg = "unknown key; remove it or check its spelling"
            else:
                shown = ", ".join(keys[:KEYS_SHOWN]) + (f" and {len(keys) - KEYS_SHOWN} more"
                                                        if len(keys) > KEYS_SHOWN else "")
                msg = f"unknown keys {shown}; remove them or check their spelling"
            lines.append(f"{source}: {where}: {msg}" if where else f"{source}: {msg}")
            continue
        if kind == "extra_forbidden":
            msg = (f"unknown setting; use one of: {', '.join(model.model_fields)}" if model is not None
                   else "unknown key; remove it or check its spelling")
        elif kind == "missing":
            msg = "required key is missing; add it"
        elif kind == "value_error":         # our own validators' words, without pydantic's prefix
            msg = msg.removeprefix("Value error, ")
        if model is not None:
            key = f"{source}.{where or '<settings>'}"
            if kind in ("extra_forbidden", "missing"):
                lines.append(f"{key}: {msg}")
            else:
                lines.append(f"{key} = {shorten(repr(e['input']), VALUE_CHARS)}: {msg[:1].lower()}{msg[1:]}"
                             f"{_default(model, loc)}")
        elif not where:
            lines.append(f"{source}: {msg}" if kind == "value_error" else f"{source}: <top level>: {msg}")
        else:
            lines.append(f"{source}: {where}: {msg}")
    if len(problems) > limit:
        more = len(problems) - limit
        lines.append(f"{source}: and {more} more problem{'s' * (more != 1)}")
    return sep.join(lines)


def no_bool_as_number(cls: Any, value: Any, info: Any) -> Any:
    """A pydantic ``field_validator("*", mode="before")``: YAML's true and false are no numbers, though
    pydantic would read them as 1 and 0, so a field that takes numbers only refuses them."""
    field = cls.model_fields.get(info.field_name or "")
    if field is not None and _holds_bool(value) and _numbers_only(field.annotation):
        raise ValueError("takes a number, not true or false")
    return value


def _holds_bool(value: Any) -> bool:
    return isinstance(value, bool) or (isinstance(value, (list, tuple)) and any(isinstance(v, bool) for v in value))


def _numbers_only(annotation: Any) -> bool:
    """Whether a field's type takes numbers (int, float, or tuples and lists of them) and never a bool."""
    leaves, todo = set(), [annotation]
    while todo:
        t = todo.pop()
        args = typing.get_args(t)
        if args and typing.get_origin(t) is not typing.Literal:
            todo.extend(args)
        elif isinstance(t, type) or t is Any:
            leaves.add(t)
    return bool(leaves & {int, float}) and not leaves & {bool, Any}
