"""``hubsgo``: train, evaluate and inspect HUBS-GO runs.

    hubsgo train TASK [--agent hubsgo|hdqn|ddqn|...] [--model SPEC] [--steps N] [--seed S] [--out DIR] [--resume]
                      [--stop-at STEP] [--init-from RUN [--transfer critic,high,low] [--restart-schedules]]
    hubsgo revise RUN_DIR --model NEW_SPEC [--steps TOTAL] [--stop-at STEP] [--no-train]
    hubsgo evaluate RUN_DIR [--episodes K]
    hubsgo subgoals RUN_DIR
    hubsgo tasks [TASK_OR_CATALOGUE ...] [--model SPEC]
    hubsgo diagnose RUN_DIR [--chains 4]
    hubsgo sweep SWEEP.yaml [--backend local|ray] [--workers K] [--variants NAME ...] [--tasks NAME ...]
    hubsgo report SWEEP_DIR
    hubsgo review RUN_DIR [--threshold 0.2] [--out DIR] [--no-gif]
    hubsgo render RUN_DIR [--out FILE.gif] [--seed N]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import traceback

import numpy as np
from pathlib import Path
from typing import Any, Sequence

__all__ = ["main", "build_parser"]

#: optional modules -> the extra of hubsgo-ppl that installs them
EXTRAS = {"robosuite": "robosuite", "mujoco": "robosuite", "ray": "ray"}


def _fmt_ranking(table: dict[str, Any]) -> str:
    lines = [f"G* from {table['num_samples']:,} critic samples (most probable sub-goal sets):",
             f"{'rank':>4}  {'P(sample)':>9}  {'P(exact)':>8}  sub-goals"]
    for i, r in enumerate(table["ranking"], 1):
        exact = "" if r.get("exact_prob") is None else f"{r['exact_prob']:.4f}"
        tie = "  ≈ tie with the one above" if r.get("near_tie") and i > 1 else ""
        lines.append(f"{i:>4}  {r['prob']:>9.4f}  {exact:>8}  {{{', '.join(r['subgoals'])}}}{tie}")
    lines.append("marginals P(w=1): " + ", ".join(f"{n}={p:.2f}" for n, p in table["marginals"].items()))
    if table["ranking"] and not table["ranking"][0]["subgoals"]:
        lines.append("the most probable set is empty: no sub-goal's evidence outweighs the prior's pull towards "
                     "small sets; positive edges in the spec let in what the successes achieve: `hubsgo review RUN` "
                     "suggests them in RUN/review/suggested_spec.yaml, and `hubsgo revise RUN --model "
                     "RUN/review/suggested_spec.yaml --no-train` reads G* again under them")
    return "\n".join(lines)


def cmd_train(args: argparse.Namespace) -> int:
    from .experiments.run import RunConfig, check_resume, train

    agent, seed = args.agent or "hubsgo", 0 if args.seed is None else args.seed
    out = Path(args.out) if args.out else Path("runs") / f"{args.task}-{agent}-s{seed}"
    if args.resume:     # flags given that would change the run are refused; the run's own values pass
        check_resume(out, args.task, agent=args.agent, seed=args.seed, model=args.model, graph=args.graph,
                     low_level=args.low_level, overrides=args.set or [], init_from=args.init_from)
    if (args.transfer is not None or args.restart_schedules) and args.init_from is None:
        from .experiments.run import RunError

        flag = "--transfer names what to take" if args.transfer is not None else "--restart-schedules is about what is taken"
        raise RunError(f"{flag} from the run given by --init-from; add --init-from RUN")
    cfg = RunConfig(task=args.task, agent=agent, model=args.model, graph=args.graph, steps=args.steps,
                    seed=seed, low_level=args.low_level, overrides=args.set or [], init_from=args.init_from,
                    transfer=args.transfer.split(",") if args.transfer is not None else None,
                    restart_schedules=args.restart_schedules, checkpoint_steps=args.checkpoint_steps)
    summary = train(cfg, out, resume=args.resume, progress=not args.no_progress, stop_at=args.stop_at)
    _print_summary(summary, out)
    return 0


def _fmt_transfer(init: dict[str, Any]) -> str:
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
    if init.get("defaults"):
        text += "; transfer defaults: " + ", ".join(f"loop.{k}={v}" for k, v in init["defaults"].items())
    return text


def _print_summary(summary: dict[str, Any], out: Path) -> None:
    if summary.get("init_from"):
        print(_fmt_transfer(summary["init_from"]))
    state = "" if summary["finished"] else "  (paused before its budget; continue with --resume)"
    print(f"run: {summary['run_dir']}  episodes={summary['episodes']}  env_steps={summary['env_steps']}  "
          f"wall={summary['wall_time']:.0f}s{state}")
    if summary.get("settled"):
        st = summary["settled"]
        print(f"settled at env step {st['step']:,}: {st['rate']:.0%} of the last {st['window']} training episodes "
              "succeeded; G* is read from the critic refitted on the recent successes at its settled power")
    table_path = out / "subgoals.json"
    if table_path.exists() and summary["finished"]:
        print(_fmt_ranking(json.loads(table_path.read_text())))


def _names(items: list[str]) -> str:
    return ", ".join(items) or "none"


def cmd_revise(args: argparse.Namespace) -> int:
    from .experiments.revise import apply_revision
    from .experiments.run import RunConfig, RunError, train

    run_dir = Path(args.run_dir)
    if args.no_train and args.stop_at is not None:
        raise RunError("--stop-at pauses the training after the revision, and --no-train trains nothing; give one "
                       "of them")
    r = apply_revision(run_dir, args.model, steps=args.steps, train_after=not args.no_train)
    print(f"revision {r['revision']} of {run_dir} at env step {r['env_steps']:,} (episode {r['episode']}): "
          f"{r['spec_before']} -> {r['spec_after']}")
    print(f"  sub-goals dropped: {_names(r['subgoals_dropped'])}; added: {_names(r['subgoals_added'])}")
    print(f"  edges added: {_names(r['edges_added'])}; dropped: {_names(r['edges_dropped'])}; "
          f"re-signed: {_names(r['edges_resigned'])}; graph {r['graph']}, prior {r['prior']}, "
          f"likelihood {r['likelihood']}, inference {r['inference']}")
    k = r["kept"]
    if r.get("critic_learned", True):
        print(f"  carried over by name: {k['theta']} unary factors, {k['couplings']} couplings, {k['high_outputs']} "
              f"high-level outputs; new: {_names(r['new']['subgoals'] + r['new']['edges'])}; the critic's optimiser "
              f"restarts")
    else:
        print(f"  the critic had not updated yet, so it starts as the revised spec says (every factor from its prior "
              f"and signs); carried over by name: {k['high_outputs']} high-level outputs")
    print(f"  recorded in {run_dir / 'revisions' / format(r['revision'], '03d')} and {run_dir / 'revisions.csv'}")
    if r.get("finished"):
        print(f"the run had taken its budget, so it stays finished; {run_dir / 'subgoals.json'} holds the revised "
              f"critic's G*, read from the same recent successes; to train on: hubsgo train {_run_task(run_dir)} "
              f"--out {run_dir} --resume --steps TOTAL")
        print(_fmt_ranking(json.loads((run_dir / "subgoals.json").read_text())))
        return 0
    if args.no_train:
        print(f"continue with: hubsgo train {_run_task(run_dir)} --out {run_dir} --resume")
        return 0
    summary = train(RunConfig(task=_run_task(run_dir)), run_dir, resume=True, progress=not args.no_progress,
                    stop_at=args.stop_at)
    _print_summary(summary, run_dir)
    return 0


def _run_task(run_dir: Path) -> str:
    from .experiments.run import run_config

    return str(run_config(run_dir)["task_ref"])


def cmd_evaluate(args: argparse.Namespace) -> int:
    from .experiments.run import evaluate

    r = evaluate(args.run_dir, episodes=args.episodes, seed=args.seed,
                 break_cycles=False if args.no_break_cycles else None)
    line = (f"{r['agent']} on {r['task']}: greedy return {r['mean_return']:.4f} ± {r['se_return']:.4f} (s.e.), "
            f"success {r['success_rate']:.2f} over {r['episodes']} episodes")
    if "optimal_return" in r:
        line += f"; optimal {r['optimal_return']:.4f} ({100 * r['fraction_of_optimal']:.1f}% of it)"
    print(line)
    return 0


def cmd_subgoals(args: argparse.Namespace) -> int:
    from .experiments.run import G_STAR_SAMPLES, RunError, load_run, subgoal_table

    run_dir = Path(args.run_dir)
    if args.samples is not None and args.samples < 1:
        raise RunError(f"--samples must be a positive number of critic samples, got {args.samples}")
    path = run_dir / "subgoals.json"
    table = None
    if path.exists() and not args.recompute and args.samples is None:    # --samples N asks for a new readout
        try:
            table = json.loads(path.read_text(encoding="utf-8"))
            _fmt_ranking(table)
        except (UnicodeDecodeError, ValueError, KeyError, TypeError, AttributeError, IndexError):
            print(f"hubsgo: note: {path} is damaged; G* is recomputed from the checkpoint", file=sys.stderr)
            table = None
    if table is None:
        resolved, env, agent, _ = load_run(run_dir)
        with contextlib.closing(env):
            if not (hasattr(agent, "filter") and hasattr(agent.filter, "critic")):
                raise RunError(f"{run_dir}: agent {resolved['agent']!r} has no sub-goal critic; "
                               "train with --agent hubsgo to learn sub-goal sets")
            table = subgoal_table(agent.g_star_critic(), list(env.unwrapped.subgoal_names),
                                  G_STAR_SAMPLES if args.samples is None else args.samples)
    print(_fmt_ranking(table))
    return 0


def cmd_tasks(args: argparse.Namespace) -> int:
    from .envs import get_task, tasks

    if args.model is not None and not args.task:
        from .experiments.run import RunError

        raise RunError("--model checks a spec against the tasks named: `hubsgo tasks TASK --model SPEC`")
    chosen = {str(t): get_task(t) for t in args.task} if args.task else tasks()
    for name, info in chosen.items():
        cat = info.catalogue
        print(f"{name}  ({info.family}, gymnasium id {info.env_id})")
        if cat.description:
            print(f"    {cat.description.strip()}")
        for sg in cat.subgoals:
            desc = f": {sg.description}" if sg.description else ""
            print(f"    - {sg.name} [{sg.kind}]{desc}")
        if args.task:
            _check_task(name, info, args.model)
    return 0


def _check_task(name: str, info: Any, model: str | None) -> None:
    """What `hubsgo train` checks before a run, without training: a maze's reachability and optimum,
    and the critic spec the run would use."""
    from .experiments.run import RunConfig, resolve

    if info.family == "minigrid":
        from .envs.minigrid.bfs import check_reachable, optimal_steps_range

        never = check_reachable(name)       # a goal no sequence reaches: SpecError
        if never is None:
            print("    reachability: too many states to check exactly; a coarser check over cells found nothing wrong")
        elif never:
            print(f"    reachability: WARNING: no reachable state achieves {', '.join(never)}")
        else:
            low, high = optimal_steps_range(name)
            shortest = (f"{low} steps" if low == high else
                        f"{low}-{high} steps, by the start direction (drawn at random each episode)")
            print(f"    reachability: the goal and every sub-goal can be reached; shortest solution {shortest}")
    from .specs import list_model_specs

    if model is None and f"{info.name}-specific" not in list_model_specs():
        print("    critic spec: none built in for this task; check yours with --model SPEC")
        return
    from .experiments.run import note_unlinked_goals, warn_goals_left_out

    resolved = resolve(RunConfig(task=name, agent="hubsgo", model=model))
    spec = resolved["model_spec"]
    left = resolved.get("subgoals")
    n_edges = len(spec["edges"])
    print(f"    critic spec {resolved['model']!r}: {len(spec['subgoals'])} sub-goals"
          + (f" (a subset: {', '.join(left)})" if left else "") + f", {n_edges} edge{'s' * (n_edges != 1)}, prior "
          f"{spec['prior']['name']}, likelihood {spec['likelihood']['name']}: valid for this task")
    warn_goals_left_out(resolved["model"], resolved["task_ref"], left)      # as `hubsgo train` says them
    note_unlinked_goals(resolved)


def cmd_diagnose(args: argparse.Namespace) -> int:
    import pandas as pd

    from .diagnostics.diagnose import diagnose
    from .experiments.run import RunError

    for flag, value, least in (("--chains", args.chains, 1), ("--draws", args.draws, 2), ("--burn-in", args.burn_in, 0)):
        if value < least:
            raise RunError(f"{flag} must be at least {least}, got {value}")
    result = diagnose(args.run_dir, chains=args.chains, draws=args.draws, burn_in=args.burn_in)
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


def cmd_sweep(args: argparse.Namespace) -> int:
    from .experiments.sweep import run_sweep

    result = run_sweep(args.sweep, backend=args.backend, workers=args.workers, out=args.out,
                       progress=not args.no_progress, variants=args.variants, tasks=args.tasks)
    print(f"sweep {result['sweep_dir']}: {result['finished']} finished, {result['skipped']} skipped "
          f"(already done), {result['retried']} retried, {len(result['failed'])} failed")
    for f in result["failed"]:
        print(f"  failed: {f}")
    return 1 if result["failed"] else 0


def cmd_report(args: argparse.Namespace) -> int:
    from .experiments.report import write_report

    paths = write_report(args.sweep_dir, out=args.out, sweep=args.sweep)
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    return 0


def cmd_review(args: argparse.Namespace) -> int:
    from .diagnostics.review import review

    out = Path(args.out) if args.out else Path(args.run_dir) / "review"
    r = review(args.run_dir, threshold=args.threshold, out=out, gif=not args.no_gif, dead_band=args.dead_band,
               num_samples=args.samples, top_k=args.top_k, last=args.last, seed=args.seed)
    g = r["g_star"]
    tie = "  (near tie with the next)" if g.get("near_tie") else ""
    settled = (f"settled at env step {r['settled_step']:,}" if r.get("settled_step") is not None
               else "not settled yet")
    print(f"review of {r['run_dir']} ({r['task']}, {r['model']}) at env step {r['env_steps']:,} "
          f"(episode {r['episodes']}; {settled})")
    print(f"G*: {{{', '.join(g['subgoals'])}}}  P={g['prob']:.3f}{tie}")
    print("marginals P(w=1): " + ", ".join(f"{n}={p:.2f}" for n, p in r["marginals"].items()))
    t = r["trend"]
    if t["delta"] is not None:
        signed = (f"{d:+.2f}".replace("-0.00", "+0.00") for d in t["delta"].values())   # no "-0.00"
        print(f"trend since step {t['env_steps']} ({t['since']}): "
              + ", ".join(f"{n} {d}" for n, d in zip(t["delta"], signed)))
    flagged = [f"{c['u']}--{c['v']} (you: {c['human']}, J={c['J']:+.2f})" for c in r["flagged_edges"]]
    print(f"flagged edges (learned sign contradicts yours): {'; '.join(flagged) or 'none'}")
    drops = [f"{d['name']} (P={d['marginal']:.2f})" for d in r["suggested_drops"]]
    prior_only = (" (the critic has not updated on this run yet: its starting values, not what this run learned)"
                  if drops and not r.get("critic_updates", 1) else "")
    print(f"suggested drops (P(w=1) < {r['threshold']:.2f}): {', '.join(drops) or 'none'}{prior_only}")
    held = [f"{d['name']} ({d['success_frequency']:.0%}; edges to {', '.join(d['positive_edges']) or 'none'})"
            for d in r["held_by_edges"]]
    print(f"in G*, held by your positive edges, skipped by most successes: {'; '.join(held) or 'none'}")
    up = [f"{d['name']} (P={d['marginal']:.2f}, {d['success_frequency']:.0%}; edges to {', '.join(d['positive_edges'])})"
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
    else:
        print("achieved on recent successes: no successful episode yet")
    for kind, name in r["files"].items():
        print(f"{kind}: {out / name}")
    if "suggested_spec" in r["files"]:
        from .diagnostics.review import revise_flags

        flags = revise_flags(r)
        finished = (" (the run has taken its budget: --no-train reads G* again under the revised spec; --steps "
                    "TOTAL trains on)" if flags else "")
        print(f"to revise: edit {out / r['files']['suggested_spec']}, then "
              f"`hubsgo revise {r['run_dir']} --model {out / r['files']['suggested_spec']}{flags}`{finished}")
    return 0


def cmd_render(args: argparse.Namespace) -> int:
    from .diagnostics.render import render_episode
    from .diagnostics.review import CHOSEN_SHOWN, format_chosen

    r = render_episode(args.run_dir, args.out, seed=args.seed, tile_size=args.tile_size, fps=args.fps)
    outcome = "success" if r["success"] else "no success"
    print(f"{r['path']}: {r['frames']} frames, one greedy episode of {r['length']} steps (env seed {r['env_seed']}, "
          f"return {r['return']:.4f}, {outcome}); sub-goals chosen: {format_chosen(r['chosen'], limit=CHOSEN_SHOWN)}")
    return 0


class UsageError(Exception):
    """A command line argparse refuses; ``main`` prints it as one line instead of the usage block."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):       # argparse prints the usage and exits; say it in one line instead
        raise UsageError(f"{message}; see `{self.prog} --help`")


def _seed(text: str) -> int:
    """A seed as numpy's generators take it: a whole number, 0 or more."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a seed is a whole number, 0 or more; got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"a seed is a whole number, 0 or more; got {value}")
    return value


#: what the progress bar of `hubsgo train` shows (experiments/callbacks.py, ProgressBarCallback)
TRAIN_EPILOG = """progress bar, after each episode:
  return       mean episode return over the last 20 episodes
  success      success rate over the last 20 episodes
  p_filter     the filter probability: the probability that the high level chooses its next sub-goal
               from Ĝt, the critic's sampled set, instead of from every open sub-goal; it rises
               over training
  critic_loss  the sub-goal critic's loss in its last updates (HUBS-GO only)
"""


def build_parser() -> argparse.ArgumentParser:
    from .agents.factory import agent_names
    from .experiments.run import CHECKPOINT_STEPS

    p = _Parser(prog="hubsgo", description="HUBS-GO: Bayesian sub-goal optimisation for HRL")
    sub = p.add_subparsers(dest="command", required=True)

    t = sub.add_parser("train", help="train an agent on a task and write a run directory",
                       formatter_class=argparse.RawDescriptionHelpFormatter, epilog=TRAIN_EPILOG)
    t.add_argument("task", help="task name (see `hubsgo tasks`) or a catalogue .yaml")
    t.add_argument("--agent", choices=agent_names(), help="default hubsgo")
    t.add_argument("--model", help="critic spec: a built-in name (e.g. keydoor-specific) or a .yaml path")
    t.add_argument("--graph", choices=["specific", "fully_connected", "independent"],
                   help="override the spec's graph preset")
    t.add_argument("--steps", type=int, help="environment-step budget (default: per task family)")
    t.add_argument("--seed", type=_seed, help="default 0")
    t.add_argument("--out", help="run directory (default runs/TASK-AGENT-sSEED)")
    t.add_argument("--resume", action="store_true", help="continue the run in --out from its checkpoint")
    t.add_argument("--low-level", choices=["learned", "scripted"], help="low level (default: per family)")
    t.add_argument("--set", action="append", metavar="KEY=VALUE",
                   help="override a hyperparameter, e.g. --set loop.option_steps=30 (repeatable)")
    t.add_argument("--checkpoint-steps", type=int, default=CHECKPOINT_STEPS, metavar="N",
                   help=f"env steps between checkpoints, which --resume continues from (default {CHECKPOINT_STEPS:,}; "
                        "a resumed run keeps its own)")
    t.add_argument("--stop-at", type=int, metavar="STEP",
                   help="pause once this env step is reached (checkpointed; the schedules still span --steps): "
                        "review, then `hubsgo revise` or --resume")
    t.add_argument("--init-from", metavar="RUN",
                   help="start from this run's critic, high level and low level, sub-goals matched by name")
    t.add_argument("--transfer", metavar="PARTS",
                   help="with --init-from: which parts, comma-separated from critic,high,low (default: all that apply)")
    t.add_argument("--restart-schedules", action="store_true",
                   help="with --init-from: start the transferred parts' exploration schedules afresh (default: "
                        "where the source run left them)")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(func=cmd_train)

    rv = sub.add_parser("revise", help="continue a HUBS-GO run with a revised critic spec (add or drop sub-goals, "
                                       "add, drop or re-sign edges, change the prior or the likelihood)")
    rv.add_argument("run_dir")
    rv.add_argument("--model", required=True, help="the revised critic spec (.yaml path or built-in name)")
    rv.add_argument("--steps", type=int, help="total env-step budget to train to (default: the run's)")
    rv.add_argument("--stop-at", type=int, metavar="STEP", help="pause once this env step is reached")
    rv.add_argument("--no-train", action="store_true", help="only revise the checkpoint; continue later with --resume")
    rv.add_argument("--no-progress", action="store_true", help="no progress bar")
    rv.set_defaults(func=cmd_revise)

    e = sub.add_parser("evaluate", help="greedy return and success rate of a trained run")
    e.add_argument("run_dir")
    e.add_argument("--episodes", type=int, default=10)
    e.add_argument("--seed", type=_seed, default=None, help="evaluation seed (default: derived from the run's)")
    e.add_argument("--no-break-cycles", action="store_true",
                   help="evaluate the bare greedy low level; by default a step in a state where it already "
                        "acted greedily for the same sub-goal in the episode is random, as in training")
    e.set_defaults(func=cmd_evaluate)

    s = sub.add_parser("subgoals", help="print the learned sub-goal sets G* of a HUBS-GO run")
    s.add_argument("run_dir")
    s.add_argument("--samples", type=int, metavar="N",
                   help="recompute G* from the checkpoint with N critic samples (default: the run's subgoals.json, "
                        "else 10,000)")
    s.add_argument("--recompute", action="store_true", help="recompute from the checkpoint")
    s.set_defaults(func=cmd_subgoals)

    d = sub.add_parser("diagnose", help="ArviZ summary, trace/forest/posterior plots, MRF graph, netCDF")
    d.add_argument("run_dir")
    d.add_argument("--chains", type=int, default=4)
    d.add_argument("--draws", type=int, default=2000)
    d.add_argument("--burn-in", type=int, default=256)
    d.set_defaults(func=cmd_diagnose)

    w = sub.add_parser("sweep", help="run a grid of tasks x agents x variants x seeds (resumable)")
    w.add_argument("sweep", help="sweep grid .yaml (e.g. sweeps/quick.yaml) or a built-in sweep name")
    w.add_argument("--backend", choices=["local", "ray"], default="local")
    w.add_argument("--workers", type=int, default=2)
    w.add_argument("--out", help="sweep directory (default runs/sweeps/NAME)")
    w.add_argument("--variants", nargs="+", metavar="NAME", help="run only these variants (rows) of the grid")
    w.add_argument("--tasks", nargs="+", metavar="NAME", help="run only these tasks (columns) of the grid")
    w.add_argument("--no-progress", action="store_true")
    w.set_defaults(func=cmd_sweep)

    r = sub.add_parser("report", help="tables (as the paper's Tables 1-2), learning curves and a CSV")
    r.add_argument("sweep_dir")
    r.add_argument("--out", help="report folder (default SWEEP_DIR/report)")
    r.add_argument("--sweep", help="report only this grid's tasks, variants and seeds (a sweep .yaml or built-in "
                                   "name), for a folder several sweeps ran into; default: the folder's sweep.yaml")
    r.set_defaults(func=cmd_report)

    v = sub.add_parser("review", help="mixed-initiative review of a HUBS-GO run: G*, marginals and their trend, "
                                      "learned couplings against your edge signs, suggested spec changes")
    v.add_argument("run_dir")
    v.add_argument("--threshold", type=float, default=0.2, help="suggest dropping sub-goals with P(w=1) below this")
    v.add_argument("--dead-band", type=float, default=0.1,
                   help="couplings with |J| at most this have no sign (neither contradict nor suggest one)")
    v.add_argument("--out", help="review folder (default RUN_DIR/review; its review.json is the trend's baseline)")
    v.add_argument("--no-gif", action="store_true", help="skip the greedy-episode GIF (MiniGrid mazes)")
    v.add_argument("--seed", type=_seed, default=None, help="evaluation seed of the GIF's episode")
    v.add_argument("--samples", type=int, default=10_000, help="critic samples for G*")
    v.add_argument("--top-k", type=int, default=5, help="sub-goal sets listed")
    v.add_argument("--last", type=int, default=20, help="episodes of metrics.csv summarised")
    v.set_defaults(func=cmd_review)

    n = sub.add_parser("render", help="animated GIF of one greedy episode on a MiniGrid maze, sub-goals marked")
    n.add_argument("run_dir")
    n.add_argument("--out", help="GIF to write (default RUN_DIR/episode.gif)")
    n.add_argument("--seed", type=_seed, default=None, help="evaluation seed (default: derived from the run's)")
    n.add_argument("--tile-size", type=int, default=32, help="pixels per grid cell")
    n.add_argument("--fps", type=float, default=6.0, help="frames per second")
    n.set_defaults(func=cmd_render)

    k = sub.add_parser("tasks", help="list the tasks and their sub-goal catalogues; given a task or catalogue, "
                                     "check it (and --model) as `hubsgo train` would, without training")
    k.add_argument("task", nargs="*", help="tasks or catalogue .yaml files to check (default: list every task)")
    k.add_argument("--model", help="a critic spec to check against the tasks given")
    k.set_defaults(func=cmd_tasks)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    from .envs import UnknownTaskError
    from .experiments.io import CheckpointError
    from .experiments.report import ReportError
    from .experiments.run import RunError
    from .specs import SpecError

    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:
            raise UsageError(f"unrecognized arguments: {' '.join(extra)}; see `hubsgo {args.command} --help`")
    except UsageError as exc:
        print(f"hubsgo: error: {exc}", file=sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:     # the reader went away (`hubsgo ... | head`): stop quietly, as Unix tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())       # no second error when Python flushes stdout at exit
        return 1
    except (SpecError, RunError, CheckpointError, ReportError, UnknownTaskError, FloatingPointError) as exc:
        msg = str(exc).strip().replace("\n", "; ")
        print(f"hubsgo: error: {msg}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        module = (exc.name or "").split(".")[0]
        if module not in EXTRAS:
            raise               # not an optional extra: a broken install or a bug, keep the traceback
        what = " ".join(str(a) for a in (args.command, getattr(args, "task", None)) if a)
        print(f"hubsgo: error: `hubsgo {what}` needs {module}, which is not installed; install the "
              f'{EXTRAS[module]} extra: pip install "hubsgo-ppl[{EXTRAS[module]}]"', file=sys.stderr)
        return 2
    except OSError as exc:      # a folder that cannot be written, a full disk: the file and the reason
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"hubsgo: error: {where}{exc.strerror or exc}; check the folder's permissions and free space",
              file=sys.stderr)
        return 2
    except Exception as exc:    # no check of ours names this: one line, and the traceback on request
        if os.environ.get("HUBSGO_TRACEBACK"):
            raise
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        msg = " ".join(str(exc).split())[:300]
        print(f"hubsgo: error: unexpected {type(exc).__name__}: {msg} (in {Path(frame.filename).name}, line "
              f"{frame.lineno}); HUBSGO_TRACEBACK=1 shows the traceback", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
