"""A first catalogue for one of MiniGrid's registered environments, read from its seeded layouts: a
sub-goal for each kind of object the agent can take or open there, the goal, and the actions these
need. It is a start for the user's own catalogue (docs/minigrid.md), not a judgement of what matters:
the critic learns that, and the user adds what the layouts cannot show (rooms, cells, the mission).

An object whose colour is the same in every layout is named by colour (``red_key``); one whose colour
changes between layouts by its type alone (``key``), as the layouts draw it at random.
"""

from __future__ import annotations

import re
from collections import Counter
from typing import Any

import yaml

from .registered import PROBE_RESETS, _inner, _quiet_reset, rewarded_actions

__all__ = ["draft_catalogue", "draft_text"]

_TAKEN = ("key", "ball", "box")


def _layouts(gym_id: str) -> tuple[list[list[tuple[str, str, bool]]], list[str]]:
    """(type, colour, locked) of the objects of each seeded layout, walls, floor and lava left out; and
    the actions on which the environment's own ``step`` pays."""
    env = _inner(gym_id, gym_id)
    try:
        seen = []
        for seed in range(PROBE_RESETS):
            _quiet_reset(env, seed)
            grid = env.grid
            objs = [(o.type, o.color, bool(getattr(o, "is_locked", False))) for o in grid.grid
                    if o is not None and o.type not in ("wall", "floor", "lava")]
            objs += [(o.contains.type, o.contains.color, False) for o in grid.grid
                     if o is not None and o.type == "box" and o.contains is not None]
            if env.carrying is not None:
                objs.append((env.carrying.type, env.carrying.color, False))
            seen.append(objs)
        return seen, rewarded_actions(type(env))
    finally:
        env.close()


def draft_catalogue(gym_id: str) -> dict[str, Any]:
    """The catalogue (as YAML would hold it) of the objects that ``gym_id``'s seeded layouts have."""
    layouts, paid = _layouts(gym_id)
    n = len(layouts)
    every = Counter(k for objs in layouts for k in set((t, c) for t, c, _ in objs))
    types = Counter(t for objs in layouts for t in set(t for t, _, _ in objs))
    subgoals: list[dict[str, Any]] = []

    def add(kind: str, name: str, args: dict[str, Any]) -> None:
        if name not in {s["name"] for s in subgoals}:
            subgoals.append({"name": name, "kind": kind, **({"args": args} if args else {})})

    for t in _TAKEN:
        if not types[t]:
            continue
        fixed = sorted(c for (u, c), k in every.items() if u == t and k == n)
        for c in fixed:
            add("carrying", f"{c}_{t}", {"type": t, "color": c})
        if not fixed:
            add("carrying", t, {"type": t})
    locked = Counter(c for objs in layouts for t, c, lock in set(objs) if t == "door" and lock)
    unlocked = [{c for t, c, lock in objs if t == "door" and not lock} for objs in layouts]
    if locked:
        add("door_open", "locked_door", {"locked": True})
    if any(unlocked):       # the doors not locked at reset, by colour where every layout has that colour
        fixed = sorted(set.intersection(*unlocked))
        for c in fixed:
            add("door_open", f"{c}_door", {"color": c, "locked": False} if locked else {"color": c})
        if not fixed:
            add("door_open", "door", {"locked": False} if locked else {})
    add("goal", "goal", {})
    actions = ["left", "right", "forward"]
    if any(types[t] for t in _TAKEN):
        actions.append("pickup")
    if sum(1 for s in subgoals if s["kind"] == "carrying") > 1:
        actions.append("drop")          # MiniGrid's hands hold one object: a second needs the first put down
    if types["door"] or types["box"]:
        actions.append("toggle")
    actions += [a for a in paid if a not in actions]        # the action the environment rewards (GoToDoor: done)
    name = re.sub(r"-v\d+$", "", gym_id.split(":")[-1]).lower().removeprefix("minigrid-").removeprefix("babyai-")
    task = re.sub(r"[^a-z0-9]+", "_", name).strip("_")
    return {"task": task, "family": "minigrid", "options": {"gym_id": gym_id, "actions": actions},
            "subgoals": subgoals}


def draft_text(cat: dict[str, Any]) -> str:
    """A :func:`draft_catalogue` as YAML, one sub-goal a line."""
    lines = [f"task: {cat['task']}", "family: minigrid",
             f"options: {{gym_id: {cat['options']['gym_id']}, actions: [{', '.join(cat['options']['actions'])}]}}",
             "subgoals:"]
    lines += [f"  - {yaml.safe_dump(s, default_flow_style=True, sort_keys=False).strip()}" for s in cat["subgoals"]]
    return "\n".join(lines) + "\n"
