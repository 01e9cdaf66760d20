"""How the commands print what a run holds: G* as a ranking, a transfer, a run's summary."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["format_ranking", "format_transfer", "print_summary", "names"]


def format_ranking(table: dict[str, Any]) -> str:
    lines = [f"G* from {table['num_samples']:,} critic samples (most probable sub-goal sets):",
             f"{'rank':>4}  {'P(sample)':>9}  {'P(exact)':>8}  sub-goals"]
    for i, r in enumerate(table["ranking"], 1):
        exact = "" if r.get("exact_prob") is None else f"{r['exact_prob']:.4f}"
        tie = "  ≈ tie with the one above" if r.get("near_tie") and i > 1 else ""
        lines.append(f"{i:>4}  {r['prob']:>9.4f}  {exact:>8}  {{{', '.join(r['subgoals'])}}}{tie}")
    lines.append("marginals P(w=1): " + ", ".join(f"{n}={p:.2f}" for n, p in table["marginals"].items()))
    if table.get("updates") == 0:
        lines.append(_never_updated(table))
    elif table["ranking"] and not table["ranking"][0]["subgoals"]:
        lines.append("the most probable set is empty: no sub-goal's evidence outweighs the prior's pull towards "
                     "small sets; positive edges in the spec let in what the successes achieve: `hubsgo review RUN` "
                     "suggests them in RUN/review/suggested_spec.yaml, and `hubsgo revise RUN --model "
                     "RUN/review/suggested_spec.yaml --no-train` reads G* again under them")
    return "\n".join(lines)


_TRAIN_LONGER = "train longer (`hubsgo train TASK --out RUN --resume --steps N`, N above the run's budget)"


def _never_updated(table: dict[str, Any]) -> str:
    """Why a critic that never updated did not: no success (no evidence), or successes before its first
    update, which waits for the high level's transitions (``successes`` and ``critic_starts`` of
    ``subgoals.json``; a file written without them gets both reasons)."""
    successes, starts = table.get("successes"), table.get("critic_starts") or {}
    source = table.get("critic_from")
    # what the prior's sets rest on: the spec's edges, or the prior alone where it has none (independent, or
    # fully_connected without a spec of one's own, whose couplings start where the prior puts them)
    edgeless = table.get("spec_edges") == 0 or table.get("factors", {}).get("pairwise") == {}
    alone = "the spec has no edges, so the prior alone" if edgeless else "your edges alone"
    if source:
        return (f"the critic never updated in this run: these sets are those of the critic transferred from "
                f"{source} (--init-from), not your edges alone; {_TRAIN_LONGER}")
    if successes == 0:
        return ("the critic never updated: no training episode succeeded, so it had no evidence, and these sets are "
                f"its prior's ({alone}); {_TRAIN_LONGER}")
    if successes:
        when = ("the high level's learning_starts or batch_size and then loop.critic_every minibatches"
                if not starts else f"{starts['transitions']:,} high-level transitions (options); this run stored "
                                   f"{starts['stored']:,}")
        return (f"{successes} training episode{'s' * (successes != 1)} succeeded, but the critic had not started "
                f"updating yet (it starts after {when}); these sets are its prior's ({alone}); "
                f"{_TRAIN_LONGER}")
    return ("the critic never updated: either no training episode succeeded or the high level had not yet stored "
            "the transitions its first update waits for (high.learning_starts); these sets are its prior's "
            f"({alone}); {_TRAIN_LONGER}")


def format_transfer(init: dict[str, Any]) -> str:
    parts = []
    for part, words in (("critic", "critic"), ("high", "high level"), ("low", "low level")):
        m = init["mapped"].get(part)
        if m is None:
            continue
        if part == "critic":
            parts.append(f"critic ({m['subgoals']} sub-goals, {m['edges']} edges by name)")
        else:
            parts.append(f"{words} ({next(iter(m.values()))} {next(iter(m))} by name)")
    text = (f"initialised from {init['run']} ({init['agent']} on {init['task']}, {init['env_steps']:,} env steps): "
            + ", ".join(parts))
    if init.get("schedules"):
        text += "; schedules continued: " + ", ".join(f"loop.{k}={v:g}" for k, v in init["schedules"].items())
    if "critic" in init.get("parts", []):
        text += "; where no critic sample holds what the agent has achieved, Ĝt completes it"
    return text


def print_summary(summary: dict[str, Any], out: Path) -> None:
    if summary.get("init_from"):
        print(format_transfer(summary["init_from"]))
    state = "" if summary["finished"] else "  (paused before its budget; continue with --resume)"
    print(f"run: {summary['run_dir']}  episodes={summary['episodes']}  env_steps={summary['env_steps']}  "
          f"wall={summary['wall_time']:.0f}s{state}")
    if summary.get("settled"):
        st = summary["settled"]
        print(f"settled at env step {st['step']:,}: {st['rate']:.0%} of the last {st['window']} training episodes "
              "succeeded; G* is read from the critic refitted on the recent successes at its settled power")
    table_path = out / "subgoals.json"
    if table_path.exists() and summary["finished"]:
        print(format_ranking(json.loads(table_path.read_text())))


def names(items: list[str]) -> str:
    return ", ".join(items) or "none"
