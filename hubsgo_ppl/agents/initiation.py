"""Initiation sets of the options, learned from the options the high level has tried.

An option "reach sub-goal g" can succeed only from some achieved sets: a locked door opens only while
its key is carried, a goal behind a closed door is out of reach. The critic's MRF says which sub-goals
belong together, not in which order, and a high level's Q(s, g) tells a feasible option from an
infeasible one only by the discount of the steps it wastes (ten steps cost a factor 0.99^10 = 0.90),
so early in training, and on a new layout after a transfer, a large share of the options chosen cannot
succeed from where they start.

:class:`InitiationSets` counts, per achieved set h at an option's start (the sub-goals that held
then, by name) and per sub-goal g, the options towards g started from h (``tries``) and those that
achieved g (``hits``). Sub-goal g is *blocked* at h once ``after`` options started from h have not
achieved it once, while an option has achieved it from a set that holds every sub-goal of h and
more: what g needs is then something achieved later, a key for its door, an open door for the goal.
Before g has been achieved anywhere nothing says what it needs, so nothing blocks it; one success
from h opens it there for good, so an option that succeeds from h only now and then (opening a door
in passing on the way to the goal) is not blocked. Where sub-goals are positions, achieved only while
the agent stands there (FourRoom's doorways), a set is where the agent stands, not what it has done,
and an option that an early low level cannot yet finish within ``option_steps`` from one doorway was
reached from the empty set, which holds less; so it is not blocked. Two rules were measured and
dropped (docs/results.md, "Learned initiation sets"): blocking wherever g was reached from any other
set, and blocking a success rate under 1/K of g's best rate elsewhere. The loop leaves blocked sub-goals
out of a choice whenever it reads Ĝt (with probability ε_filter; ``loop.initiation_tries``), so a
share of the choices still reads G0 and can undo a block by a success. This is a tabular initiation
classifier over the sub-goal abstraction, keyed by names, so it carries over to a revised spec and to a
similar task (``hubsgo train --init-from``, with the high level).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np

__all__ = ["InitiationSets"]


class InitiationSets:
    """Per (achieved set, sub-goal) counts of options tried and options that achieved their sub-goal."""

    def __init__(self, names: Sequence[str], after: int):
        if int(after) < 1:
            raise ValueError(f"loop.initiation_tries must be a positive integer (0: off), got {after!r}")
        self.names = list(names)
        self.after = int(after)
        self._tries: dict[frozenset[int], np.ndarray] = {}
        self._hits: dict[frozenset[int], np.ndarray] = {}

    @staticmethod
    def _key(achieved: np.ndarray) -> frozenset[int]:
        return frozenset(int(i) for i in np.flatnonzero(achieved))

    def record(self, achieved: np.ndarray, goal: int, success: bool) -> None:
        """An option towards ``goal`` started where ``achieved`` (N,) held; ``success``: it achieved it."""
        key = self._key(achieved)
        if key not in self._tries:
            self._tries[key] = np.zeros(len(self.names), dtype=np.int64)
            self._hits[key] = np.zeros(len(self.names), dtype=np.int64)
        self._tries[key][goal] += 1
        if success:
            self._hits[key][goal] += 1

    def blocked(self, achieved: np.ndarray) -> np.ndarray:
        """(N,) bool: the sub-goals blocked at ``achieved`` (module docstring)."""
        key = self._key(achieved)
        tries = self._tries.get(key)
        if tries is None:
            return np.zeros(len(self.names), dtype=bool)
        hits = self._hits[key]
        out = (tries >= self.after) & (hits == 0)
        for g in np.flatnonzero(out):       # reached from a set that holds more than this one
            out[g] = any(key < other for other, h in self._hits.items() if h[g] > 0)
        return out

    def counts(self, achieved: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(tries, hits) of the options started at ``achieved``, each (N,)."""
        key = self._key(achieved)
        zero = np.zeros(len(self.names), dtype=np.int64)
        return self._tries.get(key, zero).copy(), self._hits.get(key, zero).copy()

    # -- checkpointing: by name, so that a revised or a transferred run maps it -------------------------
    def state_dict(self) -> dict[str, Any]:
        rows = []
        for key in sorted(self._tries, key=lambda k: sorted(k)):
            rows.append({"achieved": [self.names[i] for i in sorted(key)],
                         "tries": {n: int(t) for n, t in zip(self.names, self._tries[key]) if t},
                         "hits": {n: int(h) for n, h in zip(self.names, self._hits[key]) if h}})
        return {"names": list(self.names), "sets": rows}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Counts by name: an achieved set that names a sub-goal this run lacks is dropped (it is another
        set here), as are the counts of such a sub-goal; a sub-goal new here starts at zero."""
        pos = {n: i for i, n in enumerate(self.names)}
        self._tries, self._hits = {}, {}
        for row in state.get("sets", []):
            if any(n not in pos for n in row["achieved"]):
                continue
            key = frozenset(pos[n] for n in row["achieved"])
            tries = np.zeros(len(self.names), dtype=np.int64)
            hits = np.zeros(len(self.names), dtype=np.int64)
            for n, t in row["tries"].items():
                if n in pos:
                    tries[pos[n]] = int(t)
            for n, h in row["hits"].items():
                if n in pos:
                    hits[pos[n]] = int(h)
            self._tries[key], self._hits[key] = tries, hits
