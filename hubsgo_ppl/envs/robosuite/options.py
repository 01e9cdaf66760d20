"""The options a robosuite catalogue lists (``options.cubes``, ``options.pads``, ``options.colours``),
checked in one place: 1 to ``most`` distinct items of the right kind, else one line naming the
catalogue and the option (docs/arms.md, "Scenes and their options"); and its numeric options
(``horizon``, ``control_freq``, ...), each a positive number."""

from __future__ import annotations

import math

from typing import Any, Callable

from ...specs import SpecError

__all__ = ["COLOURS", "DEFAULT_HORIZON", "POSITIVE", "colour_option", "listed_option", "positive_options",
           "scene_options"]

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


#: control steps before truncation where the catalogue does not set ``horizon``
DEFAULT_HORIZON = 500

#: the numeric options of a robosuite catalogue -> whether it counts (a whole number) and its unit
POSITIVE = {"horizon": (True, "control steps"), "control_freq": (True, "control steps per second"),
            "travel_clearance": (False, "metres"), "wall_height": (False, "metres")}


def positive_options(catalogue: Any, options: dict[str, Any]) -> None:
    """Refuse, in one line naming the catalogue and the key, a numeric option of :data:`POSITIVE` that
    is not a positive number (a whole one where it counts steps)."""
    for key, (whole, unit) in POSITIVE.items():
        if key not in options:
            continue
        value = options[key]
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not number or not value > 0 or (whole and value != int(value)):
            raise SpecError(f"{getattr(catalogue, 'source', 'catalogue')}: options.{key}: {value!r} is not a "
                            f"positive {'whole ' if whole else ''}number of {unit}")
    if "control_freq" in options:
        from robosuite.macros import SIMULATION_TIMESTEP

        most = round(1 / SIMULATION_TIMESTEP)   # faster, a control step runs no simulation step: nothing moves
        if options["control_freq"] > most:
            raise SpecError(f"{getattr(catalogue, 'source', 'catalogue')}: options.control_freq: "
                            f"{options['control_freq']!r} is faster than the simulation's {most} steps per second; "
                            f"give 1 to {most}")


def _noise_ok(value: Any) -> bool:
    """robosuite's initial-joint noise: null (none), ``default``, or ``{magnitude: >= 0, type: gaussian|uniform}``."""
    if value is None or value == "default":
        return True
    if not isinstance(value, dict) or set(value) != {"magnitude", "type"}:
        return False
    magnitude = value["magnitude"]
    # the noise is added to the joint angles: past half a turn it only makes the start unstable
    return (isinstance(magnitude, (int, float)) and not isinstance(magnitude, bool) and 0 <= magnitude <= math.pi
            and value["type"] in ("gaussian", "uniform"))


def _table_ok(value: Any) -> bool:
    """The table's full size: three positive numbers (length, width, thickness in metres)."""
    return (isinstance(value, (list, tuple)) and len(value) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 for v in value))


#: the robosuite robots a scene takes: one fixed-base arm whose action is (dx, dy, dz, gripper) and whose
#: gripper has the two finger pads the grasp predicate reads (a two-arm, mobile, legged or dexterous-hand
#: robot has a longer action or other grippers)
ROBOTS = ("Panda", "Sawyer", "UR5e", "IIWA", "Jaco", "Kinova3")


def _robot_ok(value: Any) -> bool:
    return isinstance(value, str) and value in ROBOTS


def _seed_ok(value: Any) -> bool:
    return value is None or (isinstance(value, int) and not isinstance(value, bool) and value >= 0)


#: the other scene options a catalogue may set -> (check, what a valid value is)
SCENE_OPTIONS: dict[str, tuple[Callable[[Any], bool], str]] = {
    "initialization_noise": (_noise_ok, "null, default or {magnitude: radians, 0 to 3.14, type: gaussian or uniform}"),
    "table_full_size": (_table_ok, "three positive numbers of metres (length, width, thickness)"),
    "robots": (_robot_ok, f"one of the single arms: {', '.join(ROBOTS)}"),
    "seed": (_seed_ok, "a whole number, 0 or more"),
    "placement_initializer": (lambda value: value is None, "set from Python (a robosuite sampler), not in a catalogue"),
}


def scene_options(catalogue: Any, options: dict[str, Any]) -> None:
    """Refuse, in one line naming the catalogue and the key, a scene option of :data:`SCENE_OPTIONS` whose
    value robosuite would fail on deep inside the scene's construction."""
    for key, (ok, what) in SCENE_OPTIONS.items():
        if key in options and not ok(options[key]):
            raise SpecError(f"{getattr(catalogue, 'source', 'catalogue')}: options.{key}: {options[key]!r} is not "
                            f"{what}")
