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
from typing import Any, Mapping

import numpy as np
import yaml

from ..experiments.io import RunFileError, write_json, write_text
from ..experiments.logger import read_csv_rows
from ..experiments.run import RunError, load_run, task_goals
from .review_findings import (DEAD_BAND, achieved_frequencies, compare_couplings, held_up_by_edges,
                              human_edge_signs, negative_edges_against_successes, prior_against_successes,
                              suggested_drops, suggested_links)
from .review_report import CHOSEN_SHOWN, format_chosen, render_markdown
from .review_spec import revise_flags, suggested_spec

__all__ = ["review", "compare_couplings", "human_edge_signs", "suggested_drops", "prior_against_successes",
           "negative_edges_against_successes", "held_up_by_edges", "suggested_links", "suggested_spec",
           "revise_flags", "marginal_trend", "achieved_frequencies", "metrics_summary", "render_markdown",
           "plot_review_graph", "format_chosen", "CHOSEN_SHOWN", "DEAD_BAND", "REVIEW_FORMAT"]

REVIEW_FORMAT = 1


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

    from .mrf_figure import mrf_graph_figure
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
