"""The review's suggestions applied to the run's spec: ``suggested_spec.yaml``, a starting point for
the human to edit and pass to ``hubsgo revise``."""

from __future__ import annotations

from typing import Any, Mapping

__all__ = ["suggested_spec", "revise_flags"]


def suggested_spec(r: Mapping[str, Any], spec: Mapping[str, Any], rare: float = 0.5) -> dict[str, Any]:
    """The spec ``spec`` (a run's resolved model spec) with the suggestions of review ``r`` applied, for
    the human to edit and pass to ``hubsgo revise``:

    - drop each suggested sub-goal that fewer than ``rare`` of the recent successes achieved, with its
      edges (without successes, or before the critic's first update, nothing is dropped: the marginals
      are then the prior's, not evidence);
    - give each flagged edge its learned sign, and each edge left unknown with a learned sign that sign;
    - remove each negative edge whose two sub-goals every recent success achieved, and, once the critic
      has updated, each positive edge that holds in G*, or above the drop threshold, a sub-goal most
      recent successes skipped;
    - where G* leaves out the goal that every recent success reached, add the positive edges of
      :func:`suggested_links` (what most successes achieved, linked to the goal); a graph preset without
      edges (``independent``) becomes ``specific`` with those links as its only edges (the edges the
      spec lists acted on nothing under that preset, and stay out).

    Otherwise a sub-goal every success achieved that G* leaves out needs an edge only the human can
    choose, so it is left as it is. The name gains ``-reviewed``. At least one sub-goal stays."""
    learned = r.get("critic_updates", 1) > 0
    drop = {d["name"] for d in r.get("suggested_drops", []) if learned and d.get("success_frequency") is not None
            and d["success_frequency"] < rare}
    keep = [n for n in spec["subgoals"] if n not in drop]
    if not keep:
        keep, drop = list(spec["subgoals"]), set()
    sign = {frozenset((c["u"], c["v"])): c["learned"] for c in r.get("flagged_edges", []) + r.get("suggested_signs", [])}
    unlink = {frozenset((c["u"], c["v"])) for c in r.get("negative_edges_achieved_together", [])}
    if learned:     # G* and the marginals before the first update are the prior's: no edge holds them up yet
        unlink |= {frozenset((d["name"], v)) for d in r.get("held_by_edges", []) + r.get("held_up_by_edges", [])
                   for v in d["positive_edges"]}
    edges, seen = [], set()
    for u, v, s in spec.get("edges", []):
        e = frozenset((u, v))
        seen.add(e)
        if u not in drop and v not in drop and e not in unlink:
            edges.append([u, v, sign.get(e, s)])
    for c in r.get("suggested_signs", []):         # an unknown edge of a graph preset, not in the spec
        e = frozenset((c["u"], c["v"]))
        if e not in seen and not e & drop:
            edges.append([c["u"], c["v"], c["learned"]])
    links = [c for c in r.get("suggested_links", []) if not {c["u"], c["v"]} & drop]
    independent = bool(links) and spec.get("graph") == "independent"
    linked = {frozenset((c["u"], c["v"])) for c in links}
    # an independent graph's listed edges acted on nothing: the links are its only edges
    edges = [] if independent else [e for e in edges if frozenset(e[:2]) not in linked]
    edges += [[c["u"], c["v"], "positive"] for c in links]
    out = {**spec, "name": f"{spec['name']}-reviewed", "subgoals": keep, "edges": edges}
    if independent:
        out["graph"] = "specific"
    out["task"] = spec.get("task") or r.get("task")      # a spec written without one names the run's task
    return {k: v for k, v in out.items() if v is not None}


def revise_flags(r: Mapping[str, Any]) -> str:
    """What the suggested ``hubsgo revise`` command needs after its spec: `` --no-train`` for a run that
    has taken its budget (it stays finished, and G* is read again under the revised spec; ``--steps
    TOTAL`` would train on), nothing otherwise."""
    return " --no-train" if "steps" in r and r["env_steps"] >= r["steps"] else ""
