"""A small name -> class registry shared by the prior and likelihood registries."""

from __future__ import annotations

import inspect
from typing import Any, Callable


def make_register(table: dict[str, type], kind: str, required: str) -> Callable[[str], Callable[[type], type]]:
    def register(name: str) -> Callable[[type], type]:
        if not isinstance(name, str) or not name:
            raise ValueError(f"a {kind} needs a non-empty string name, got {name!r}")

        def deco(cls: type) -> type:
            if not callable(getattr(cls, required, None)):
                raise TypeError(f"{kind} {cls.__name__} must define a {required}() method")
            if name in table and table[name] is not cls:
                raise ValueError(f"{kind} name {name!r} is already registered to {table[name].__name__}; pick another name")
            table[name] = cls
            cls.registered_name = name
            return cls

        return deco

    return register


def build(table: dict[str, type], kind: str, name: str, *args: Any, **params: Any):
    if name not in table:
        raise ValueError(f"unknown {kind} {name!r}; registered: {', '.join(sorted(table))}")
    cls = table[name]
    accepted = [p for p in list(inspect.signature(cls.__init__).parameters)[1 + len(args):]]
    unknown = sorted(set(params) - set(accepted))
    if unknown:
        raise ValueError(f"{kind} {name!r}: unknown parameter(s) {', '.join(unknown)}; accepted: {', '.join(accepted) or 'none'}")
    return cls(*args, **params)
