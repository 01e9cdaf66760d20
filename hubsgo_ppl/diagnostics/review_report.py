"""review.md: the review (the content of review.json) written for people."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from .review_spec import revise_flags

__all__ = ["render_markdown", "format_chosen", "CHOSEN_SHOWN", "FEW_SUCCESSES"]

#: the sub-goals chosen in a reported episode are listed up to this many runs of one sub-goal, then counted
CHOSEN_SHOWN = 30


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
        dropped = ("no sub-goal dropped and no edge removed for what G* holds: the critic's starting values are "
                   "your spec's prior, and a spec changes only for what this run's critic learned"
                   if not r.get("critic_updates", 1) else
                   "sub-goals dropped only where fewer than half of the recent successes achieved them")
        lines += ["", f"`suggested_spec.yaml`, next to this file, is your spec with these changes applied ({dropped}"
                  f"{added}): edit "
                  f"it, then `hubsgo revise {r['run_dir']} --model "
                  f"{Path(r.get('review_dir', '.')) / r['files']['suggested_spec']}{revise_flags(r)}`."]

    lines += ["", f"## G*: the most probable sub-goal sets ({r['num_samples']:,} critic samples)", "",
              "P(sample): a set's frequency among the critic's MH samples; P(exact): its exact probability by "
              "enumeration (blank where there are too many sub-goals to enumerate).", "",
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
    elif (r["achieved"]["metrics"] or {}).get("successes"):
        lines.append("- No successful episode in the filter's window, which a revision that added sub-goals started "
                     "afresh (its stored episodes do not say whether they achieved the new ones): the suggestions "
                     "above that read the recent successes have none to read yet.")
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
