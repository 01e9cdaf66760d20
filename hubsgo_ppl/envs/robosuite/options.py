"""The options a robosuite catalogue lists (``options.cubes``, ``options.pads``, ``options.colours``),
checked in one place: 1 to ``most`` distinct items of the right kind, else one line naming the
catalogue and the option (docs/arms.md, "Scenes and their options")."""

from __future__ import annotations

from typing import Any, Callable

from ...specs import SpecError

__all__ = ["COLOURS", "colour_option", "listed_option"]

#: the cube colours a catalogue may name (``options.colours`` of PushAnyOne, ``options.cubes`` of StackCubes)
COLOURS = {"red": (1, 0, 0, 1), "green": (0, 1, 0, 1), "blue": (0, 0, 1, 1), "yellow": (1, 1, 0, 1),
           "magenta": (1, 0, 1, 1), "cyan": (0, 1, 1, 1)}


def listed_option(catalogue: Any, key: str, value: Any, most: int, ok: Callable[[Any], bool], what: str
                  ) -> tuple[Any, ...]:
    """A catalogue option that lists 1 to ``most`` distinct items, each passing ``ok``, as a tuple; else
    one line naming the catalogue, the option and ``what`` it should be."""
    items = tuple(value) if isinstance(value, (list, tuple)) else (value,)
    if not all(ok(v) for v in items) or not 1 <= len(items) <= most or len(set(items)) != len(items):
        raise SpecError(f"{getattr(catalogue, 'source', 'catalogue')}: options.{key}: {list(items)} is not "
                        f"1 to {most} distinct {what}")
    return items


def colour_option(catalogue: Any, key: str, value: Any, most: int) -> tuple[str, ...]:
    """A catalogue option that lists distinct cube colours of :data:`COLOURS`."""
    return listed_option(catalogue, key, value, most, lambda c: isinstance(c, str) and c in COLOURS,
                         f"colours of: {', '.join(COLOURS)}")
