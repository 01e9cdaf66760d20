"""``hubsgo review RUN``: the mixed-initiative review of a HUBS-GO run.

The human gave the critic a spec (sub-goals and signed edges, ``models/<task>-specific.yaml``); the
critic has learned q(w; lambda) from the agent's experience. The review puts the two side by side so
that the human can revise the spec:

- G*: the most probable sub-goal sets under the critic (``SubgoalCritic.ranking``);
- the marginals P(w_i = 1) and their trend since the previous review in the same folder (the first
  review: since the first row of ``critic_history.csv``);
- the learned couplings J next to the human's edge signs; an edge is *flagged* where the learned sign
  contradicts the human's (a positive edge with J < -dead_band, a negative edge with J > dead_band);
  edges the human left unknown whose |J| exceeds the dead band get a *suggested sign*;
- *suggested drops*: sub-goals the critic has pushed below ``threshold`` (P(w_i = 1) < threshold);
- where G*'s top set and the recent successes disagree (:func:`prior_against_successes`): a sub-goal
  the human's positive edges keep in G* though most successes did without it, and one every success
  achieved that G* leaves out; and a sub-goal outside G* that those edges keep above the drop
  threshold though most successes did without it (:func:`held_up_by_edges`);
- negative edges the successes contradict (:func:`negative_edges_against_successes`): two sub-goals
  the human said exclude each other that every recent success achieved;
- what the agent achieves: the frequency of each sub-goal over the filter's recent successful
  episodes (``CriticFilter.outcomes()``), and the success rate over the last K episodes of
  ``metrics.csv`` (with per-sub-goal frequencies when it has ``visited/<name>`` columns);
- the step (env_steps) and episode of the checkpoint reviewed.

Usage::

    hubsgo review runs/keydoor-hubsgo-s0                   # writes runs/keydoor-hubsgo-s0/review/
    hubsgo review runs/keydoor-hubsgo-s0 --threshold 0.3 --out reviews/kd --no-gif

    from hubsgo_ppl.diagnostics.review import review
    result = review("runs/keydoor-hubsgo-s0", threshold=0.2)      # the content of review.json

Into ``RUN/review/`` (or ``--out``), each file written atomically: ``review.json`` (for programs; it
keeps this review's marginals, which the next review's trend is measured against), ``review.md`` (for
people), ``suggested_spec.yaml`` (the run's spec with the review's suggestions applied,
:func:`suggested_spec`: a starting point to edit and pass to ``hubsgo revise``), ``mrf_graph.png`` (the
learned MRF with the marginals) and, on MiniGrid mazes, ``episode.gif`` (one greedy episode,
:mod:`hubsgo_ppl.diagnostics.render`; ``--no-gif`` skips it).
The review reads the run and writes only into its own folder; it refuses runs without a sub-goal
critic (h-DQN and the flat baselines) with one line.
"""

from __future__ import annotations

import contextlib
import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import yaml

from ..experiments.io import RunFileError, write_json, write_text
from ..experiments.logger import read_csv_rows
from ..experiments.run import RunError, load_run, task_goals

__all__ = ["review", "compare_couplings", "human_edge_signs", "suggested_drops", "prior_against_successes",
           "negative_edges_against_successes", "held_up_by_edges", "suggested_links", "suggested_spec",
           "marginal_trend", "achieved_frequencies", "metrics_summary", "render_markdown", "plot_review_graph", "format_chosen", "DEAD_BAND", "REVIEW_FORMAT"]

REVIEW_FORMAT = 1
#: the sub-goals chosen in a reported episode are listed up to this many runs of one sub-goal, then counted
CHOSEN_SHOWN = 30
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


def suggested_spec(r: Mapping[str, Any], spec: Mapping[str, Any], rare: float = 0.5) -> dict[str, Any]:
    """The spec ``spec`` (a run's resolved model spec) with the suggestions of review ``r`` applied, for
    the human to edit and pass to ``hubsgo revise``:

    - drop each suggested sub-goal that fewer than ``rare`` of the recent successes achieved, with its
      edges (without successes, or before the critic's first update, nothing is dropped: the marginals
      are then the prior's, not evidence);
    - give each flagged edge its learned sign, and each edge left unknown with a learned sign that sign;
    - remove each negative edge whose two sub-goals every recent success achieved, and each
      positive edge that holds in G*, or above the drop threshold, a sub-goal most recent successes
      skipped;
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


def _previous_review(path: Path, names: list[str]) -> dict[str, Any] | None:
    try:
        prev = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    marg = prev.get("marginals") if isinstance(prev, dict) else None
    if not isinstance(marg, dict) or list(marg) != names:
        return None             # another run's review, or an unreadable one: not a baseline
    return {"source": "previous review", "env_steps": prev.get("env_steps"), "episodes": prev.get("episodes"),
            "marginals": {n: float(marg[n]) for n in names}}


def _first_history_row(path: Path, names: list[str]) -> dict[str, Any] | None:
    try:
        rows = read_csv_rows(path) if path.exists() else []
    except RunFileError:
        return None             # the trend then starts at this review
    if not rows or any(n not in rows[0] for n in names):
        return None
    try:
        first = rows[0]
        return {"source": "first row of critic_history.csv", "env_steps": int(float(first["env_steps"])),
                "episodes": int(float(first["episode"])), "marginals": {n: float(first[n]) for n in names}}
    except (KeyError, ValueError):
        return None


def marginal_trend(marginals: Mapping[str, float], baseline: dict[str, Any] | None) -> dict[str, Any]:
    """``{"since", "env_steps", "episodes", "previous", "delta"}``: delta = current - previous per sub-goal
    (all None without a baseline)."""
    if baseline is None:
        return {"since": None, "env_steps": None, "episodes": None, "previous": None, "delta": None}
    prev = baseline["marginals"]
    return {"since": baseline["source"], "env_steps": baseline.get("env_steps"),
            "episodes": baseline.get("episodes"), "previous": dict(prev),
            "delta": {n: float(p) - float(prev[n]) for n, p in marginals.items()}}


def achieved_frequencies(outcomes: Any, names: list[str]) -> dict[str, Any]:
    """Per sub-goal, the share of the filter's recent successful episodes that achieved it."""
    arr = _outcome_array(outcomes, len(names))
    if arr.shape[0] == 0:
        return {"episodes": 0, "frequency": None}
    return {"episodes": int(arr.shape[0]), "frequency": dict(zip(names, arr.mean(0).tolist()))}


def metrics_summary(path: Path, names: list[str], last: int = 20) -> dict[str, Any] | None:
    """The last ``last`` training episodes of ``metrics.csv``: success rate, mean return and, where the
    log has ``visited/<name>`` columns, each sub-goal's frequency over those that succeeded."""
    rows = read_csv_rows(path, required=("episode", "return", "success")) if path.exists() else []
    if not rows:
        return None
    rows = rows[-last:]
    try:
        success = [float(r.get("success") or 0) > 0 for r in rows]
        first = int(float(rows[0]["episode"]))
        mean_return = float(np.mean([float(r.get("return") or 0) for r in rows]))
    except ValueError as exc:
        raise RunFileError(f"{path}: damaged, a value is not a number ({exc})") from None
    out: dict[str, Any] = {"episodes": len(rows), "first_episode": first, "success_rate": float(np.mean(success)),
                           "mean_return": mean_return, "successes": int(sum(success)), "frequency": None}
    cols = [f"visited/{n}" for n in names]
    if all(c in rows[0] for c in cols) and any(success):
        won = [r for r, s in zip(rows, success) if s]
        out["frequency"] = {n: float(np.mean([float(r[c] or 0) > 0 for r in won])) for n, c in zip(names, cols)}
    return out


def _check_args(threshold: float, top_k: int, num_samples: int, last: int) -> None:
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and 0.0 <= threshold <= 1.0):
        raise RunError(f"--threshold must be a probability in [0, 1], got {threshold!r}")
    if int(top_k) < 1 or int(num_samples) < 1 or int(last) < 1:
        raise RunError(f"--top-k, --samples and --last must be positive, got {top_k}, {num_samples}, {last}")


def review(run_dir: str | Path, threshold: float = 0.2, out: str | Path | None = None, gif: bool = True,
           dead_band: float = DEAD_BAND, num_samples: int = 10_000, top_k: int = 5, last: int = 20,
           seed: int | None = None) -> dict[str, Any]:
    """Review the HUBS-GO run in ``run_dir`` (see the module docstring) and write ``review.json``,
    ``review.md``, ``mrf_graph.png`` and (mazes, ``gif=True``) ``episode.gif`` into ``out`` (default
    ``RUN/review``). Returns the content of review.json. ``seed``: the GIF's evaluation seed."""
    from .render import read_run_config

    _check_args(threshold, top_k, num_samples, last)
    run_dir = Path(run_dir)
    cfg = read_run_config(run_dir)
    if cfg is not None and cfg.get("agent") != "hubsgo":
        raise RunError(_refusal(run_dir, cfg.get("agent")))
    resolved, env, agent, ckpt = load_run(run_dir)
    with contextlib.closing(env):
        if not (hasattr(agent, "filter") and hasattr(agent.filter, "critic")):
            raise RunError(_refusal(run_dir, resolved.get("agent")))
        return _review(run_dir, resolved, env, agent, threshold, Path(out) if out else run_dir / "review",
                       gif, dead_band, num_samples, top_k, last, seed)


def _refusal(run_dir: Path, agent: Any) -> str:
    return (f"{run_dir}: agent {agent!r} has no sub-goal critic to review (the review compares a HUBS-GO "
            "critic with its spec); review a run trained with --agent hubsgo")


def _review(run_dir: Path, resolved: dict[str, Any], env: Any, agent: Any, threshold: float, out: Path,
            gif: bool, dead_band: float, num_samples: int, top_k: int, last: int,
            seed: int | None) -> dict[str, Any]:
    critic = agent.g_star_critic()         # once settled: refitted at the settled power (loop.settle_at)
    names = list(critic.names)
    # first, so that G* is the ranking a freshly loaded critic gives (it advances the critic's generator)
    ranking = critic.ranking(num_samples=num_samples, top_k=top_k)
    marginals = dict(zip(names, critic.marginals().detach().cpu().numpy().astype(float).tolist()))
    factors = critic.factors()
    human = human_edge_signs(resolved.get("model_spec"), critic.graph.edges)
    in_graph = {frozenset((u, v)) for u, v, _ in critic.graph.edges}
    acting = {e: s for e, s in human.items() if e in in_graph}    # a spec's edges that a preset left out act on nothing
    couplings = compare_couplings(factors["pairwise"], human, dead_band)
    spec_only = [{"u": u, "v": v, "human": s} for u, v, s in (resolved.get("model_spec") or {}).get("edges", [])
                 if frozenset((u, v)) not in {frozenset(e) for e in factors["pairwise"]}]
    outcomes = agent.filter.outcomes()
    achieved = achieved_frequencies(outcomes, names)
    top = ranking[0]["subgoals"]
    goals = [g for g in task_goals(resolved["task_ref"]) if g in names]
    baseline = _previous_review(out / "review.json", names) or _first_history_row(run_dir / "critic_history.csv", names)

    result: dict[str, Any] = {
        "format": REVIEW_FORMAT, "run_dir": str(run_dir), "task": resolved.get("task"),
        "agent": resolved.get("agent"), "model": resolved.get("model"), "graph": (resolved.get("model_spec") or {}).get("graph"),
        "seed": resolved.get("seed"), "env_steps": int(agent.env_steps), "episodes": int(agent.episodes),
        # the run's budget: a run that has taken it is revised with --no-train (or trained on with --steps)
        "steps": int(resolved["hyper"]["steps"]),
        # the env step at which the agent settled (loop.settle_at; None: not yet), after which G* and the
        # marginals here come from the critic refitted on the recent successes at the likelihood's settled power
        "settled_step": getattr(agent, "settled_step", None),
        # 0: this run has not updated the critic yet (an outcome critic waits for the first success), so
        # the marginals and the suggested drops are its starting values (the prior, or a transferred critic)
        "critic_updates": int(critic.num_updates),
        "threshold": float(threshold), "dead_band": float(dead_band), "num_samples": int(num_samples),
        "names": names,
        "g_star": ranking[0],
        "ranking": ranking,
        "marginals": marginals,
        "trend": marginal_trend(marginals, baseline),
        "unary": {n: float(x) for n, x in factors["unary"].items()},
        "couplings": couplings,
        "flagged_edges": [c for c in couplings if c["contradicts"]],
        "suggested_signs": [c for c in couplings if not c["contradicts"] and c["suggestion"]],
        "spec_edges_not_in_graph": spec_only,
        "suggested_drops": suggested_drops(marginals, threshold, achieved["frequency"]),
        **prior_against_successes(top, names, achieved["frequency"], acting),
        "goals": goals,
        "held_up_by_edges": held_up_by_edges(top, marginals, achieved["frequency"], acting, threshold),
        "suggested_links": suggested_links(top, names, achieved["frequency"], goals, acting),
        "negative_edges_achieved_together": negative_edges_against_successes(outcomes, names, acting),
        "achieved": {"recent_successes": achieved, "metrics": metrics_summary(run_dir / "metrics.csv", names, last)},
        "episode": None,
        "review_dir": str(out),
        "files": {"json": "review.json", "markdown": "review.md", "mrf_graph": "mrf_graph.png"},
    }
    out.mkdir(parents=True, exist_ok=True)
    plot_review_graph(result, out / "mrf_graph.png")
    if resolved.get("family") == "minigrid" and gif:
        from .render import annotate_frames, episode_summary, record_episode, write_gif

        rec = record_episode(resolved, env, agent, seed=seed)
        write_gif(annotate_frames(rec), out / "episode.gif")
        result["episode"] = episode_summary(rec, None)
        result["files"]["gif"] = "episode.gif"
    elif resolved.get("family") != "minigrid":
        result["episode"] = {"skipped": "render supports MiniGrid mazes"}
    if resolved.get("model_spec"):
        head = (f"# {resolved['model_spec'].get('name')} with the suggestions of the review of {run_dir} at env step "
                f"{result['env_steps']:,} applied (review.md lists them).\n# Edit it, then: hubsgo revise {run_dir} "
                f"--model THIS_FILE{revise_flags(result)}\n")
        body = yaml.safe_dump(suggested_spec(result, resolved["model_spec"]), sort_keys=False, default_flow_style=None)
        write_text(out / "suggested_spec.yaml", head + body)
        result["files"]["suggested_spec"] = "suggested_spec.yaml"
    write_text(out / "review.md", render_markdown(result))
    write_json(out / "review.json", result)    # last: the next review's baseline only once all is written
    return result


def plot_review_graph(r: dict[str, Any], path: Path) -> Path:
    """The learned MRF (``diagnostics.plots.mrf_graph_figure``: node = P(w_i = 1), edge width = |J|,
    colour = sign) with the flagged edges, and the negative edges whose two sub-goals every recent success
    achieved, overlaid as red dashes and the suggested drops ringed in red."""
    import networkx as nx
    from matplotlib.lines import Line2D

    from .plots import mrf_graph_figure
    from ..experiments.io import atomic_path

    names = r["names"]
    marg = np.clip(np.array([r["marginals"][n] for n in names], dtype=float), 0.0, 1.0)
    fig = mrf_graph_figure(names, marg, [(c["u"], c["v"]) for c in r["couplings"]], [c["J"] for c in r["couplings"]],
                           title=f"review of {r['task']} at step {r['env_steps']:,}: node = P(w_i = 1), edge = learned J")
    ax = fig.axes[0]
    pos = nx.circular_layout(list(names)) if len(names) > 1 else {names[0]: np.zeros(2)}   # as mrf_graph_figure
    handles = []
    against = r["flagged_edges"] + r.get("negative_edges_achieved_together", [])
    for c in against:
        (x0, y0), (x1, y1) = pos[c["u"]], pos[c["v"]]
        ax.plot([x0, x1], [y0, y1], color="red", lw=2.5, ls=(0, (4, 3)), zorder=1.5)
    if against:
        handles.append(Line2D([], [], color="red", lw=2, ls=(0, (4, 3)),
                              label="contradicts your sign (learned J or the successes)"))
    drops = [d["name"] for d in r["suggested_drops"]]
    for n in drops:
        ax.scatter(*pos[n], s=3200, facecolors="none", edgecolors="red", linewidths=2, zorder=6)
    if drops:
        handles.append(Line2D([], [], color="red", marker="o", ls="", markerfacecolor="none", markersize=10,
                              label=f"suggested drop (P < {r['threshold']:.2f})"))
    if handles:
        signs = ax.get_legend()             # mrf_graph_figure's legend of the edge colours: keep it
        ax.legend(handles=handles, loc="lower right", fontsize=8, frameon=False)
        if signs is not None:
            ax.add_artist(signs)
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path


# -- the report for people ------------------------------------------------------------------------

def format_chosen(chosen: Sequence[str], limit: int | None = None) -> str:
    """``a, a, b`` as ``a x2, b``; past ``limit`` such runs, the count of the options left
    (a failed episode of a few thousand steps chooses a hundred sub-goals or more)."""
    out: list[list[Any]] = []
    for c in chosen:
        if out and out[-1][0] == c:
            out[-1][1] += 1
        else:
            out.append([c, 1])
    text = ", ".join(c if k == 1 else f"{c} x{k}" for c, k in out[:limit])
    if limit is not None and len(out) > limit:
        text += f", ... ({sum(k for _, k in out[limit:])} more)"
    return text


def _delta(d: float) -> str:
    text = f"{d:+.3f}"
    return "+0.000" if text == "-0.000" else text

def _set(names: Sequence[str]) -> str:
    return "{" + ", ".join(names) + "}"


def _pct(x: float | None) -> str:
    return "-" if x is None else f"{100 * x:.0f}%"


#: below this many recent successes review.md says its success frequencies are thin evidence
FEW_SUCCESSES = 5


def render_markdown(r: dict[str, Any]) -> str:
    """review.md from the content of review.json."""
    names, marg, trend = r["names"], r["marginals"], r["trend"]
    succ = r["achieved"]["recent_successes"]
    lines = [f"# Mixed-initiative review: {r['task']} ({r['agent']}, {r.get('model') or 'no spec'}, seed {r['seed']})",
             "",
             f"Run `{r['run_dir']}` at env step {r['env_steps']:,} (episode {r['episodes']}). "
             f"Suggested drops: P(w_i = 1) < {r['threshold']:.2f}; a coupling has a sign when |J| > {r['dead_band']:.2f}. "
             + (f"The agent settled at env step {r['settled_step']:,}; G* and the marginals below come from the critic "
                "refitted on its recent successes at the likelihood's settled power." if r.get("settled_step") is not None else "The agent has not settled yet."),
             "", "## Suggested changes to the spec", ""]
    changes = []
    for c in r["flagged_edges"]:
        changes.append(f"- **edge {c['u']} — {c['v']}**: you said *{c['human']}*, the critic learned J = {c['J']:+.2f} "
                       f"({c['learned']}): {c['suggestion']}.")
    for d in r["suggested_drops"]:
        note = ""
        if not r.get("critic_updates", 1):
            note = ("; the critic has not updated on this run yet: this is its starting value (your spec's prior, "
                    "or the critic it was transferred from), not what this run learned")
        elif d["success_frequency"] is not None:
            note = f"; achieved on {_pct(d['success_frequency'])} of the recent successes"
            if d["success_frequency"] >= 0.5:
                note += " (the successes need it: check before dropping)"
        changes.append(f"- **drop {d['name']}**: P(w = 1) = {d['marginal']:.2f}{note}.")
    for c in r["suggested_signs"]:
        changes.append(f"- edge {c['u']} — {c['v']} (you left it *{c['human']}*): the critic learned J = {c['J']:+.2f}; "
                       f"{c['suggestion']}.")
    for d in r["held_by_edges"]:
        edges = ", ".join(f"{d['name']} — {v}" for v in d["positive_edges"]) or "none"
        changes.append(f"- **{d['name']} is in G* but only {_pct(d['success_frequency'])} of the recent successes "
                       f"achieved it**: your positive edges hold it there ({edges}); remove them, or drop {d['name']}.")
    for d in r.get("held_up_by_edges", []):
        edges = ", ".join(f"{d['name']} — {v}" for v in d["positive_edges"])
        changes.append(f"- **{d['name']} has P(w = 1) = {d['marginal']:.2f} but only {_pct(d['success_frequency'])} of the "
                       f"recent successes achieved it**: your positive edges hold it up ({edges}), so it stays in the "
                       f"sets Ĝt the high level chooses from; remove them, or drop {d['name']}.")
    for c in r.get("negative_edges_achieved_together", []):
        changes.append(f"- **edge {c['u']} — {c['v']}**: you said *negative* (one excludes the other), yet "
                       f"{_pct(c['both_frequency'])} of the recent successes achieved both; remove it, or make it "
                       f"positive if the route needs both (an agent may also pass a sub-goal it does not need).")
    links = r.get("suggested_links", [])
    linked = {c["u"] for c in links} | {c["v"] for c in links}
    for d in r["needed_not_in_g_star"]:
        if d["name"] in linked:
            continue            # the suggested links below say what to do
        edges = ", ".join(f"{d['name']} — {v}" for v in d["positive_edges"])
        hint = (f"its positive edges ({edges}) are not enough" if edges
                else "no positive edge links it to the route")
        changes.append(f"- **every recent success achieved {d['name']}, yet G* leaves it out**: {hint}; add a positive "
                       f"edge to the sub-goal it goes with, or raise the outcome likelihood's power.")
    for c in links:
        was = f"; you said *{c['human']}*" if c["human"] else ""
        changes.append(f"- **link {c['u']} — {c['v']} (positive)**: G* leaves out {c['v']}, which every recent "
                       f"success reached, so it names no route; {_pct(c['success_frequency'])} of those successes "
                       f"achieved {c['u']}{was}.")
    n_succ = succ["episodes"]
    if changes and n_succ:
        few = (f" Only {n_succ}: a drop read from so few can remove a route the agent still needs; if unsure, train on "
               f"and review again." if n_succ < FEW_SUCCESSES else "")
        changes = [f"What the recent successes achieved is read from the {n_succ} the filter keeps.{few}", "", *changes]
    if not changes and not r.get("critic_updates", 1):
        changes = ["None yet: the critic has not updated on this run (an outcome critic waits for the first success), "
                   "so nothing it learned can weigh against your spec; train on and review after the first successes."]
    lines += changes or [f"None: every learned coupling agrees with your edge signs, and every sub-goal has "
                         f"P(w = 1) >= {r['threshold']:.2f}."]
    if "suggested_spec" in r["files"]:
        added = ("; positive edges added to the goal that G* leaves out" if r.get("suggested_links")
                 else "; nothing added")
        lines += ["", "`suggested_spec.yaml`, next to this file, is your spec with these changes applied (sub-goals "
                  f"dropped only where fewer than half of the recent successes achieved them{added}): edit "
                  f"it, then `hubsgo revise {r['run_dir']} --model "
                  f"{Path(r.get('review_dir', '.')) / r['files']['suggested_spec']}{revise_flags(r)}`."]

    lines += ["", f"## G*: the most probable sub-goal sets ({r['num_samples']:,} critic samples)", "",
              "| rank | P(sample) | P(exact) | sub-goals |", "|---:|---:|---:|---|"]
    for i, row in enumerate(r["ranking"], 1):
        exact = "" if row.get("exact_prob") is None else f"{row['exact_prob']:.4f}"
        tie = " (near tie with rank 1)" if row.get("near_tie") and i > 1 else ""
        lines.append(f"| {i} | {row['prob']:.4f} | {exact} | {_set(row['subgoals'])}{tie} |")

    if trend["since"] is None:
        since = "trend (no earlier marginals)"
    else:
        step = trend["env_steps"]
        since = f"trend since step {step:,}" if isinstance(step, int) else "trend"
        since += f" ({trend['since']})"
    freq = succ["frequency"] or {}
    lines += ["", "## Marginals P(w_i = 1)", "",
              f"| sub-goal | P(w = 1) | {since} | achieved on recent successes ({succ['episodes']}) |",
              "|---|---:|---:|---:|"]
    for n in names:
        delta = "-" if trend["delta"] is None else _delta(trend["delta"][n])
        low = " ⬇ below threshold" if marg[n] < r["threshold"] else ""
        lines.append(f"| {n} | {marg[n]:.3f}{low} | {delta} | {_pct(freq.get(n)) if freq else '-'} |")

    lines += ["", "## Couplings: your edges and what the critic learned", "",
              "| edge | your sign | learned J | learned sign | verdict |", "|---|---|---:|---|---|"]
    together = {frozenset((c["u"], c["v"])) for c in r.get("negative_edges_achieved_together", [])}
    for c in r["couplings"]:
        verdict = "**contradicts**" if c["contradicts"] else ("suggest a sign" if c["suggestion"] else "agrees"
                                                               if c["human"] != "unknown" else "-")
        if frozenset((c["u"], c["v"])) in together:
            verdict = "**the successes achieve both**"
        lines.append(f"| {c['u']} — {c['v']} | {c['human']} | {c['J']:+.3f} | {c['learned']} | {verdict} |")
    if not r["couplings"]:
        lines.append("| (the critic's graph has no edges) | | | | |")
    for e in r["spec_edges_not_in_graph"]:
        lines.append(f"| {e['u']} — {e['v']} | {e['human']} | - | not in the critic's graph | - |")

    lines += ["", "## What the agent achieves", ""]
    if succ["episodes"]:
        lines.append(f"- Over the filter's {succ['episodes']} recent successful episodes: "
                     + ", ".join(f"{n} {_pct(freq[n])}" for n in names) + ".")
    else:
        lines.append("- No successful episode yet in the filter's window: the critic has had no outcome evidence.")
    m = r["achieved"]["metrics"]
    if m:
        text = (f"- Last {m['episodes']} training episodes (metrics.csv, from episode {m['first_episode']}): success "
                f"rate {m['success_rate']:.2f}, mean return {m['mean_return']:.3f}")
        if m["frequency"]:
            text += "; on their successes: " + ", ".join(f"{n} {_pct(m['frequency'][n])}" for n in names)
        lines.append(text + ".")
    lines += ["", "## Pictures", "", "![learned MRF](mrf_graph.png)", ""]
    ep = r.get("episode")
    if ep and "frames" in ep:
        outcome = "success" if ep["success"] else "no success"
        lines += [f"One greedy episode ({ep['length']} steps, return {ep['return']:.3f}, {outcome}; sub-goals chosen: "
                  f"{format_chosen(ep['chosen'], limit=CHOSEN_SHOWN)}). Magenta: the current sub-goal's cell; cyan: the other sub-goals of Ĝt.",
                  "", "![greedy episode](episode.gif)", ""]
    elif ep and "skipped" in ep:
        lines += [f"No episode GIF: {ep['skipped']}.", ""]
    return "\n".join(lines)
