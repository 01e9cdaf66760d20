"""What a review finds, each a pure function of the critic's factors, the human's spec and the recent
successes (:mod:`hubsgo_ppl.diagnostics.review` gathers them into review.json).

- :func:`compare_couplings`: the learned couplings J next to the human's edge signs (flagged where the
  learned sign contradicts the human's, a suggested sign where the human left the edge unknown);
- :func:`suggested_drops`: sub-goals the critic pushed below the drop threshold;
- :func:`prior_against_successes` and :func:`held_up_by_edges`: sub-goals the human's positive edges
  hold in G*, or above the threshold, though most successes did without them, and sub-goals every
  success achieved that G* leaves out;
- :func:`negative_edges_against_successes`: negative edges between two sub-goals every success achieved;
- :func:`suggested_links`: positive edges that would let G* name the route the agent takes;
- :func:`achieved_frequencies`: how often the recent successes achieved each sub-goal.
"""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np

from ..experiments.run import RunError

__all__ = ["human_edge_signs", "compare_couplings", "suggested_drops", "prior_against_successes",
           "held_up_by_edges", "negative_edges_against_successes", "suggested_links", "achieved_frequencies",
           "DEAD_BAND"]

#: |J| at or below this counts as "no learned sign": it neither contradicts nor suggests a sign
DEAD_BAND = 0.1
_SIGN_WORDS = {1: "positive", -1: "negative", 0: "unknown"}


def human_edge_signs(model_spec: Mapping[str, Any] | None, graph_edges: Sequence[Sequence[Any]] = ()
                     ) -> dict[frozenset, str]:
    """The human's sign of each edge, keyed by ``frozenset({u, v})``: the spec's edges (``positive``,
    ``negative`` or ``unknown``), else the critic graph's sign. Edges a graph preset added
    (fully_connected) and the spec does not name are ``unknown``."""
    signs: dict[frozenset, str] = {}
    for u, v, s in graph_edges:
        signs[frozenset((u, v))] = _SIGN_WORDS.get(int(s), "unknown") if not isinstance(s, str) else s
    for u, v, s in (model_spec or {}).get("edges", []):
        signs[frozenset((u, v))] = str(s)
    return signs


def _learned(j: float, dead_band: float) -> str:
    return "positive" if j > dead_band else "negative" if j < -dead_band else "near zero"


def compare_couplings(pairwise: Mapping[tuple[str, str], float], human: Mapping[frozenset, str],
                      dead_band: float = DEAD_BAND) -> list[dict[str, Any]]:
    """One row per learned coupling ``(u, v) -> J`` (``critic.factors()["pairwise"]``), next to the
    human's sign: ``{"u", "v", "human", "J", "learned", "contradicts", "suggestion"}``.

    ``contradicts``: the human said positive and J < -dead_band, or negative and J > dead_band.
    ``suggestion``: for a contradiction, to flip or remove the edge; for an edge the human left
    unknown with |J| > dead_band, to declare the learned sign; otherwise None."""
    if not (isinstance(dead_band, (int, float)) and math.isfinite(dead_band) and dead_band >= 0):
        raise RunError(f"--dead-band must be a number >= 0, got {dead_band!r}")
    rows = []
    for (u, v), j in pairwise.items():
        j = float(j)
        said = human.get(frozenset((u, v)), "unknown")
        learned = _learned(j, dead_band)
        contradicts = (said == "positive" and j < -dead_band) or (said == "negative" and j > dead_band)
        suggestion = None
        if contradicts:
            suggestion = f"flip the edge to {learned} or remove it"
        elif said == "unknown" and learned != "near zero":
            suggestion = f"declare the edge {learned}"
        rows.append({"u": u, "v": v, "human": said, "J": j, "learned": learned, "contradicts": bool(contradicts),
                     "suggestion": suggestion})
    return rows


def suggested_drops(marginals: Mapping[str, float], threshold: float,
                    achieved: Mapping[str, float] | None = None) -> list[dict[str, Any]]:
    """Sub-goals with P(w_i = 1) < ``threshold``, least probable first, with how often the agent's
    recent successes achieved them (None without successes): a sub-goal that every success achieves
    and the critic still drops deserves a second look rather than a drop."""
    drops = [{"name": n, "marginal": float(p),
              "success_frequency": None if achieved is None else float(achieved.get(n, 0.0))}
             for n, p in marginals.items() if float(p) < threshold]
    return sorted(drops, key=lambda d: (d["marginal"], d["name"]))


def prior_against_successes(top: Sequence[str], names: Sequence[str], achieved: Mapping[str, float] | None,
                            human: Mapping[frozenset, str], rare: float = 0.5) -> dict[str, list[dict[str, Any]]]:
    """Where G*'s top set and the recent successes disagree, and which of the human's edges explain it.

    - ``held_by_edges``: sub-goals in the top set that fewer than ``rare`` of the recent successes
      achieved, each with the human's positive edges that pull it in (the prior, not the successes,
      keeps it there: a wrong edge to a sub-goal no route needs);
    - ``needed_not_in_g_star``: sub-goals that every recent success achieved and the top set leaves
      out, each with its positive edges (with none, the outcome likelihood's tempered evidence alone
      cannot bring it in).

    Empty lists without successes (``achieved`` None)."""
    out: dict[str, list[dict[str, Any]]] = {"held_by_edges": [], "needed_not_in_g_star": []}
    if achieved is None:
        return out
    chosen = set(top)
    for n in names:
        freq = float(achieved.get(n, 0.0))
        if n in chosen and freq < rare:
            out["held_by_edges"].append({"name": n, "success_frequency": freq,
                                         "positive_edges": _positive_edges(human, n)})
        elif n not in chosen and freq >= 1.0:
            out["needed_not_in_g_star"].append({"name": n, "success_frequency": freq,
                                                "positive_edges": _positive_edges(human, n)})
    return out


def _positive_edges(human: Mapping[frozenset, str], n: str) -> list[str]:
    """The sub-goals the human's positive edges join to ``n``, sorted."""
    return sorted(next(iter(e - {n})) for e, sign in human.items() if n in e and sign == "positive")


def held_up_by_edges(top: Sequence[str], marginals: Mapping[str, float], achieved: Mapping[str, float] | None,
                     human: Mapping[frozenset, str], threshold: float, rare: float = 0.5) -> list[dict[str, Any]]:
    """Sub-goals outside G*'s top set that the human's positive edges keep at P(w_i = 1) >= ``threshold``
    (so no drop is suggested) though fewer than ``rare`` of the recent successes achieved them:
    ``{"name", "marginal", "success_frequency", "positive_edges"}`` in the order of ``marginals``. They
    stay in the filtered sets Ĝt that the critic samples, and the high level keeps choosing them, so
    the review names them as it names such a sub-goal in G* (``held_by_edges``). Empty without
    successes."""
    if achieved is None:
        return []
    chosen = set(top)
    rows = []
    for n, p in marginals.items():
        freq = float(achieved.get(n, 0.0))
        if n in chosen or float(p) < threshold or freq >= rare:
            continue
        edges = _positive_edges(human, n)
        if edges:
            rows.append({"name": n, "marginal": float(p), "success_frequency": freq, "positive_edges": edges})
    return rows


def _outcome_array(outcomes: Any, n: int) -> np.ndarray:
    """The filter's recent successful episodes (a tensor or array) as a float array, one row of ``n``
    achieved flags per episode."""
    return np.asarray(outcomes.detach().cpu().numpy() if hasattr(outcomes, "detach") else outcomes,
                      dtype=float).reshape(-1, n)


def negative_edges_against_successes(outcomes: Any, names: Sequence[str], human: Mapping[frozenset, str],
                                     share: float = 1.0) -> list[dict[str, Any]]:
    """The human's negative edges whose two sub-goals at least ``share`` of the recent successful
    episodes (by default every one) both achieved: ``{"u", "v", "both_frequency"}`` in the order of
    ``names``. Every success, not most: an agent also passes sub-goals it does not need (a cube pushed
    across one target on its way to another), and a pair that every success achieves is one the task
    needs. An edge that says "one excludes the other" between two steps of the route the agent takes
    holds the critic's coupling negative (at the outcome likelihood's default power the successes cannot
    flip it), so the learned sign never contradicts it; the successes do. Empty without successes."""
    arr = _outcome_array(outcomes, len(names))
    if arr.shape[0] == 0:
        return []
    index = {n: i for i, n in enumerate(names)}
    rows = []
    for edge, sign in human.items():
        if sign != "negative" or len(edge) != 2 or not edge <= index.keys():
            continue
        u, v = sorted(edge, key=index.__getitem__)
        both = float((arr[:, index[u]] * arr[:, index[v]]).mean())
        if both >= share:
            rows.append({"u": u, "v": v, "both_frequency": both})
    return sorted(rows, key=lambda r: (index[r["u"]], index[r["v"]]))


def suggested_links(top: Sequence[str], names: Sequence[str], achieved: Mapping[str, float] | None,
                    goals: Sequence[str], human: Mapping[frozenset, str], rare: float = 0.5) -> list[dict[str, Any]]:
    """Positive edges that would let G* name the route the agent takes, where G* (``top``) leaves out a
    goal that every recent success reached: link to that goal each other sub-goal that at least ``rare``
    of the recent successes achieved (``achieved``: their frequencies; None without successes) and that
    has no positive edge to it yet: ``{"u", "v": the goal, "human": the spec's sign of the pair or None,
    "success_frequency"}`` in the order of ``names``.

    A G* without the goal names no route: the spec's edges do not tie what the successes need to the
    goal (a graph without edges, one whose signs are all unknown, or a goal left unlinked), and under a
    negative field the outcome evidence alone cannot bring a sub-goal in. At least half of the
    successes, as for the drops (:func:`suggested_spec` drops what fewer than half achieved): where the
    successes split between two routes, the more frequent one is linked. Where G* holds the goal,
    nothing is suggested: a sub-goal that the successes pass but the human left unlinked (a cell on the
    way) stays out, as the human's graph says."""
    if achieved is None:
        return []
    chosen = set(top)
    goal = next((g for g in goals if g not in chosen and float(achieved.get(g, 0.0)) >= 1.0), None)
    if goal is None:
        return []
    return [{"u": n, "v": goal, "human": human.get(frozenset((n, goal))), "success_frequency": float(achieved[n])}
            for n in names if n not in goals and float(achieved.get(n, 0.0)) >= rare
            and human.get(frozenset((n, goal))) != "positive"]


def achieved_frequencies(outcomes: Any, names: list[str]) -> dict[str, Any]:
    """Per sub-goal, the share of the filter's recent successful episodes that achieved it."""
    arr = _outcome_array(outcomes, len(names))
    if arr.shape[0] == 0:
        return {"episodes": 0, "frequency": None}
    return {"episodes": int(arr.shape[0]), "frequency": dict(zip(names, arr.mean(0).tolist()))}
