"""The commands that read a trained run: ``evaluate``, ``subgoals``, ``diagnose``, ``review``, ``render``."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import tempfile
from pathlib import Path

from .show import format_ranking

__all__ = ["cmd_evaluate", "cmd_subgoals", "cmd_diagnose", "cmd_review", "cmd_render"]


def _writable(target: Path, run_dir: str, default: str) -> None:
    """Refuse, before any work, to write ``target`` (a folder, or a file's folder) where the nearest existing
    folder cannot be written, e.g. a run folder on a read-only disk: the work would be lost at the end."""
    if not Path(run_dir).is_dir():
        return                  # the command names the missing run itself
    folder = target
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        return
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as exc:
        from ..experiments.run import RunError

        raise RunError(f"{folder}: cannot write here ({exc.strerror}; the default is {default}); give --out, a "
                       "place you can write") from None


def cmd_evaluate(args: argparse.Namespace) -> int:
    from ..experiments.run import evaluate

    r = evaluate(args.run_dir, episodes=args.episodes, seed=args.seed,
                 break_cycles=False if args.no_break_cycles else None)
    line = (f"{r['agent']} on {r['task']}: greedy return {r['mean_return']:.4f} ± {r['se_return']:.4f} (s.e.), "
            f"success {r['success_rate']:.2f} over {r['episodes']} episodes")
    if "optimal_return" in r:
        line += f"; optimal {r['optimal_return']:.4f} ({100 * r['fraction_of_optimal']:.1f}% of it)"
    print(line)
    return 0


def cmd_subgoals(args: argparse.Namespace) -> int:
    from ..experiments.run import G_STAR_SAMPLES, RunError, g_star_table, load_run

    run_dir = Path(args.run_dir)
    if args.samples is not None and args.samples < 1:
        raise RunError(f"--samples must be a positive number of critic samples, got {args.samples}")
    path = run_dir / "subgoals.json"
    table = None
    if path.exists() and not args.recompute and args.samples is None:    # --samples N asks for a new readout
        try:
            table = json.loads(path.read_text(encoding="utf-8"))
            format_ranking(table)
        except (UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError, IndexError):
            print(f"hubsgo: note: {path} is damaged; G* is recomputed from the checkpoint", file=sys.stderr)
            table = None
    if table is None:
        resolved, env, agent, _ = load_run(run_dir)
        with contextlib.closing(env):
            if not (hasattr(agent, "filter") and hasattr(agent.filter, "critic")):
                raise RunError(f"{run_dir}: agent {resolved['agent']!r} has no sub-goal critic; "
                               "train with --agent hubsgo to learn sub-goal sets")
            table = g_star_table(agent, list(env.unwrapped.subgoal_names), run_dir,
                                 G_STAR_SAMPLES if args.samples is None else args.samples)
    print(format_ranking(table))
    return 0


def cmd_diagnose(args: argparse.Namespace) -> int:
    import numpy as np
    import pandas as pd

    from ..diagnostics.diagnose import diagnose
    from ..experiments.run import RunError

    for flag, value, least in (("--chains", args.chains, 2), ("--draws", args.draws, 2), ("--burn-in", args.burn_in, 0)):
        if value < least:
            raise RunError(f"{flag} must be at least {least}, got {value}")
    _writable(Path(args.out) if args.out else Path(args.run_dir) / "diagnostics", args.run_dir, "RUN_DIR/diagnostics")
    result = diagnose(args.run_dir, chains=args.chains, draws=args.draws, burn_in=args.burn_in, out=args.out)
    table = result["summary"]
    with pd.option_context("display.width", 120, "display.max_columns", 20):
        print(f"ArviZ summary of q(w) from {result['chains']} chains x {result['draws']} draws:")
        print(table.to_string(float_format=lambda v: f"{v:.3f}"))
    r_hat = table["r_hat"].to_numpy(dtype=float)
    const = table["constant"].to_numpy(dtype=bool) if "constant" in table else np.zeros(len(table), bool)
    worst = np.nanmax(np.where(const, np.nan, r_hat)) if (~const).any() else float("nan")
    print(f"max r_hat over non-constant sub-goals: {worst:.4f}")
    for kind, path in result["paths"].items():
        print(f"{kind}: {path}")
    return 0


def cmd_review(args: argparse.Namespace) -> int:
    from ..diagnostics.review import review

    out = Path(args.out) if args.out else Path(args.run_dir) / "review"
    _writable(out, args.run_dir, "RUN_DIR/review")
    r = review(args.run_dir, threshold=args.threshold, out=out, gif=not args.no_gif, dead_band=args.dead_band,
               num_samples=args.samples, top_k=args.top_k, last=args.last, seed=args.seed)
    g = r["g_star"]
    tie = "  (near tie with the next)" if g.get("near_tie") else ""
    settled = (f"settled at env step {r['settled_step']:,}" if r.get("settled_step") is not None
               else "not settled yet")
    print(f"review of {r['run_dir']} ({r['task']}, {r['model']}) at env step {r['env_steps']:,} "
          f"(episode {r['episodes']}; {settled})")
    print(f"G*: {{{', '.join(g['subgoals'])}}}  P(sample)={g['prob']:.3f}{tie}")
    print("marginals P(w=1): " + ", ".join(f"{n}={p:.2f}" for n, p in r["marginals"].items()))
    t = r["trend"]
    if t["delta"] is not None:
        signed = (f"{d:+.2f}".replace("-0.00", "+0.00") for d in t["delta"].values())   # no "-0.00"
        print(f"trend since step {t['env_steps']} ({t['since']}): "
              + ", ".join(f"{n} {d}" for n, d in zip(t["delta"], signed)))
    flagged = [f"{c['u']}--{c['v']} (you: {c['human']}, J={c['J']:+.2f})" for c in r["flagged_edges"]]
    print(f"flagged edges (learned sign contradicts yours): {'; '.join(flagged) or 'none'}")
    drops = [f"{d['name']} (P(w=1)={d['marginal']:.2f})" for d in r["suggested_drops"]]
    prior_only = (" (the critic has not updated on this run yet: its starting values, not what this run learned)"
                  if drops and not r.get("critic_updates", 1) else "")
    print(f"suggested drops (P(w=1) < {r['threshold']:.2f}): {', '.join(drops) or 'none'}{prior_only}")
    held = [f"{d['name']} ({d['success_frequency']:.0%}; edges to {', '.join(d['positive_edges']) or 'none'})"
            for d in r["held_by_edges"]]
    print(f"in G*, held by your positive edges, skipped by most successes: {'; '.join(held) or 'none'}")
    up = [f"{d['name']} (P(w=1)={d['marginal']:.2f}, {d['success_frequency']:.0%}; edges to {', '.join(d['positive_edges'])})"
          for d in r.get("held_up_by_edges", [])]
    if up:
        print(f"outside G*, held up by your positive edges, skipped by most successes: {'; '.join(up)}")
    needed = [d["name"] for d in r["needed_not_in_g_star"]]
    print(f"achieved by every recent success, not in G*: {', '.join(needed) or 'none'}")
    links = [f"{c['u']}--{c['v']}" for c in r.get("suggested_links", [])]
    if links:
        print(f"G* leaves out the goal every success reached; positive edges that would let it name the route: "
              f"{'; '.join(links)}")
    signs = [f"{c['u']}--{c['v']} {c['learned']} (J={c['J']:+.2f})" for c in r.get("suggested_signs", [])]
    if signs:
        print(f"edges you left unknown, with the sign the critic learned: {'; '.join(signs)}")
    together = [f"{c['u']}--{c['v']} ({c['both_frequency']:.0%})" for c in r.get("negative_edges_achieved_together", [])]
    print(f"your negative edges, both ends achieved by every recent success: {'; '.join(together) or 'none'}")
    succ = r["achieved"]["recent_successes"]
    if succ["episodes"]:
        print(f"achieved on the {succ['episodes']} recent successes: "
              + ", ".join(f"{n} {f:.0%}" for n, f in succ["frequency"].items()))
    elif (r["achieved"].get("metrics") or {}).get("successes"):
        print(f"achieved on recent successes: none in the filter's window, which a revision that added sub-goals "
              f"started afresh, though {r['achieved']['metrics']['successes']} of the last "
              f"{r['achieved']['metrics']['episodes']} training episodes succeeded")
    else:
        print("achieved on recent successes: no successful episode yet")
    for kind, name in r["files"].items():
        print(f"{kind}: {out / name}")
    if "suggested_spec" in r["files"]:
        from ..diagnostics.review import revise_flags

        flags = revise_flags(r)
        finished = (" (the run has taken its budget: --no-train reads G* again under the revised spec; --steps "
                    "TOTAL trains on)" if flags else "")
        print(f"to revise: edit {out / r['files']['suggested_spec']}, then "
              f"`hubsgo revise {r['run_dir']} --model {out / r['files']['suggested_spec']}{flags}`{finished}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from ..diagnostics.render import render_episode
    from ..diagnostics.review import CHOSEN_SHOWN, format_chosen

    _writable(Path(args.out).parent if args.out else Path(args.run_dir), args.run_dir, "RUN_DIR/episode.gif")
    r = render_episode(args.run_dir, args.out, seed=args.seed, tile_size=args.tile_size, fps=args.fps)
    outcome = "success" if r["success"] else "no success"
    print(f"{r['path']}: {r['frames']} frames, one greedy episode of {r['length']} steps (env seed {r['env_seed']}, "
          f"return {r['return']:.4f}, {outcome}); sub-goals chosen: {format_chosen(r['chosen'], limit=CHOSEN_SHOWN)}")
    return 0
