"""A task restricted to a subset of its sub-goal catalogue: how a critic spec drops sub-goals.

A task's candidate sub-goals G0 are its catalogue's. A critic spec may list only some of them (a
human who reviewed the critic drops the misleading ones, ``hubsgo revise``); the run then works on
the task built from the catalogue with only those sub-goals, in the catalogue's order. Everything
that reads the sub-goals through the env (``subgoal_names``, ``info["subgoals"]``,
``subgoal_achieved``, ``subgoal_target``, ``subgoal_potential``) sees the subset, so the high level
has one output per listed sub-goal, the low level one goal per listed sub-goal, and the filter and
the critic one indicator per listed sub-goal. The task itself is unchanged: the layout, the
observations, the actions, the reward and success do not depend on which sub-goals are candidates
(a MiniGrid observation encodes the layout's objects, not the catalogue).

Only sub-goals the catalogue defines can be listed: the task can evaluate nothing else.

    from hubsgo_ppl.envs.subset import make_subset
    env = make_subset("keydoor_incorrect", ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"])
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import gymnasium as gym

from ..specs import SpecError
from . import _FAMILY_ENTRY, get_task
from .subgoals import Catalogue

__all__ = ["subset_catalogue", "make_subset", "check_subset", "catalogue_order"]


def check_subset(names: Sequence[str], catalogue: Sequence[str], source: str) -> None:
    """Refuse, in one line, ``names`` that the catalogue lacks (or lists twice, or none)."""
    catalogue = list(catalogue)
    if not names:
        raise SpecError(f"{source}: subgoals: none listed; list some of the task's sub-goals: {', '.join(catalogue)}")
    unknown = [n for n in names if n not in catalogue]
    if unknown:
        which = (f"sub-goal {unknown[0]!r} is" if len(unknown) == 1
                 else f"sub-goals {', '.join(repr(n) for n in unknown)} are")
        raise SpecError(f"{source}: {which} not in the task's catalogue, which can evaluate only: "
                        f"{', '.join(catalogue)}")
    dup = sorted({n for n in names if list(names).count(n) > 1})
    if dup:
        raise SpecError(f"{source}: subgoals: {', '.join(dup)} listed twice; list each sub-goal once")


def catalogue_order(names: Sequence[str], catalogue: Sequence[str]) -> list[str]:
    """``names`` in the catalogue's order."""
    chosen = set(names)
    return [n for n in catalogue if n in chosen]


def subset_catalogue(catalogue: Catalogue, names: Sequence[str]) -> Catalogue:
    """``catalogue`` with only the sub-goals ``names`` (in the catalogue's order); the same object when
    ``names`` are all of them."""
    check_subset(list(names), catalogue.names, catalogue.source)
    if list(names) == catalogue.names:
        return catalogue
    keep = set(names)
    sub = catalogue.model_copy(update={"subgoals": [sg for sg in catalogue.subgoals if sg.name in keep],
                                       "observed": catalogue.observed or list(catalogue.subgoals)})
    sub.source = catalogue.source           # layouts are named relative to the catalogue's file
    return sub


def make_subset(name_or_path: str | Path, names: Sequence[str] | None, seed: int | None = None,
                **kwargs: Any) -> gym.Env:
    """The task's env with only the sub-goals ``names`` (None: all of them, as ``envs.make``)."""
    from . import make

    if names is None:
        return make(name_or_path, seed=seed, **kwargs)
    info = get_task(name_or_path)
    cat = info.catalogue
    cat.source = str(info.catalogue_path)
    sub = subset_catalogue(cat, names)
    if sub is cat:
        return make(name_or_path, seed=seed, **kwargs)
    module, cls = _FAMILY_ENTRY[info.family].split(":")
    factory = getattr(__import__(module, fromlist=[cls]), cls)
    env = factory(catalogue=sub, **kwargs)
    if seed is not None:
        env.reset(seed=seed)
    return env
