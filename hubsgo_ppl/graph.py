"""The sub-goal graph: named candidate sub-goals and the signed edges a human drew between them.

Sec. 3.1/3.3 of the paper: the expert names the candidates G = {g_1..g_N} and the correlation edges
E = {(g_u, g_v)}, each believed positive, negative or of unknown sign. The graph fixes which pairwise
factors the MRF critic (Eq. 1) has; the signs only seed their initial values.
"""

from __future__ import annotations

import functools
from typing import Sequence

import torch

__all__ = ["SubgoalGraph", "PRESETS", "colour_classes"]

PRESETS = ("specific", "fully_connected", "independent")
_SIGNS = {1: 1, -1: -1, 0: 0}


class SubgoalGraph:
    """Named sub-goals plus signed, undirected edges ``(u, v, sign)`` with sign in {+1, -1, 0}.

    Edges are stored with ``index(u) < index(v)``; ``edge_index`` is the ``(E, 2)`` LongTensor of
    those index pairs and ``edge_sign`` the matching ``(E,)`` float tensor.

    >>> g = SubgoalGraph(["key", "door", "goal"], [("door", "key", 1)])
    >>> g.edges
    [('key', 'door', 1)]
    >>> g.preset("fully_connected").edge_sign.tolist()
    [1.0, 0.0, 0.0]
    """

    def __init__(self, names: Sequence[str], edges: Sequence[tuple[str, str, int]] = ()):
        if isinstance(names, str):
            raise TypeError("names must be a sequence of sub-goal names, not one string; wrap it in a list")
        names = list(names)
        if not names:
            raise ValueError("a sub-goal graph needs at least one sub-goal (N = 0); name some candidates")
        seen: set[str] = set()
        for name in names:
            if not isinstance(name, str) or not name:
                raise ValueError(f"sub-goal names must be non-empty strings, got {name!r}")
            if name in seen:
                raise ValueError(f"duplicate sub-goal name {name!r}; names must be unique")
            seen.add(name)
        self.names: list[str] = names
        self.n: int = len(names)
        self._pos = {name: i for i, name in enumerate(names)}

        norm: dict[tuple[int, int], int] = {}
        for k, edge in enumerate(edges):
            if len(edge) != 3:
                raise ValueError(f"edges[{k}] = {edge!r}: expected (u, v, sign) with sign in +1/-1/0")
            u, v, sign = edge
            iu, iv = self.index(u), self.index(v)
            if iu == iv:
                raise ValueError(f"edges[{k}]: self-edge on {u!r}; an edge must join two different sub-goals")
            if sign not in _SIGNS or isinstance(sign, bool):
                raise ValueError(f"edges[{k}]: sign {sign!r} is not one of +1 (positive), -1 (negative), 0 (unknown)")
            key = (min(iu, iv), max(iu, iv))
            if key in norm:
                raise ValueError(f"edges[{k}]: duplicate edge between {u!r} and {v!r}; give each pair once")
            norm[key] = int(sign)
        order = sorted(norm)
        self.edges: list[tuple[str, str, int]] = [(names[a], names[b], norm[(a, b)]) for a, b in order]
        self.edge_index: torch.Tensor = torch.tensor(order, dtype=torch.long).reshape(-1, 2)
        self.edge_sign: torch.Tensor = torch.tensor([float(norm[k]) for k in order]).reshape(-1)

    @property
    def num_edges(self) -> int:
        return len(self.edges)

    def index(self, name: str) -> int:
        """Position of ``name`` in ``names``."""
        try:
            return self._pos[name]
        except KeyError:
            raise KeyError(f"{name!r} is not a sub-goal; use one of: {', '.join(self.names)}") from None

    def preset(self, kind: str) -> "SubgoalGraph":
        """The graph under one of the paper's knowledge settings (Sec. 4.3).

        ``specific``: the edges as given; ``fully_connected``: every pair, keeping a given edge's sign
        and 0 (unknown) elsewhere; ``independent``: no edges (the Bernoulli special case of Sec. 3.3).
        """
        if kind == "specific":
            return SubgoalGraph(self.names, self.edges)
        if kind == "independent":
            return SubgoalGraph(self.names, ())
        if kind == "fully_connected":
            given = {(u, v): s for u, v, s in self.edges}
            pairs = [
                (self.names[a], self.names[b], given.get((self.names[a], self.names[b]), 0))
                for a in range(self.n)
                for b in range(a + 1, self.n)
            ]
            return SubgoalGraph(self.names, pairs)
        raise ValueError(f"unknown graph preset {kind!r}; use one of: {', '.join(PRESETS)}")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, SubgoalGraph) and self.names == other.names and self.edges == other.edges

    def __hash__(self) -> int:
        return hash((tuple(self.names), tuple(self.edges)))

    def __repr__(self) -> str:
        return f"SubgoalGraph(n={self.n}, edges={self.num_edges})"


@functools.lru_cache(maxsize=512)
def _colour_classes(n: int, pairs: tuple[tuple[int, int], ...]) -> tuple[torch.Tensor, ...]:
    adj: list[set[int]] = [set() for _ in range(n)]
    for a, b in pairs:
        adj[a].add(b)
        adj[b].add(a)
    colour: dict[int, int] = {}
    # Welsh-Powell: highest degree first keeps the number of classes (sequential steps) small.
    for i in sorted(range(n), key=lambda i: (-len(adj[i]), i)):
        used = {colour[j] for j in adj[i] if j in colour}
        c = 0
        while c in used:
            c += 1
        colour[i] = c
    k = max(colour.values()) + 1 if colour else 0
    return tuple(torch.tensor([i for i in range(n) if colour[i] == c], dtype=torch.long) for c in range(k))


def colour_classes(edge_index: torch.Tensor, n: int) -> list[torch.Tensor]:
    """Partition of the N sites into independent sets of the graph (greedy colouring).

    Sites of one class share no edge, so given the rest they are conditionally independent and can
    be flipped in parallel without changing the MH kernel's stationary distribution.
    """
    pairs = tuple(tuple(p) for p in edge_index.reshape(-1, 2).tolist())
    return list(_colour_classes(int(n), pairs))
