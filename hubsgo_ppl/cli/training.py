"""The commands that train: ``hubsgo train`` and ``hubsgo revise``."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from .show import format_ranking, names, print_summary

__all__ = ["cmd_train", "cmd_revise"]


def cmd_train(args: argparse.Namespace) -> int:
    if args.seeds is not None:
        return _train_seeds(args)
    from ..experiments.run import RunConfig, RunError, check_resume, train

    if args.workers != 1:
        raise RunError("--workers shares the seeds of --seeds between processes; one --seed trains in one")
    agent, seed = args.agent or "hubsgo", 0 if args.seed is None else args.seed
    out = Path(args.out) if args.out else Path("runs") / f"{args.task}-{agent}-s{seed}"
    if args.resume:     # flags given that would change the run are refused; the run's own values pass
        check_resume(out, args.task, agent=args.agent, seed=args.seed, model=args.model, graph=args.graph,
                     low_level=args.low_level, overrides=args.set or [], init_from=args.init_from)
    if (args.transfer is not None or args.restart_schedules) and args.init_from is None:
        flag = "--transfer names what to take" if args.transfer is not None else "--restart-schedules is about what is taken"
        raise RunError(f"{flag} from the run given by --init-from; add --init-from RUN")
    cfg = RunConfig(task=args.task, agent=agent, model=args.model, graph=args.graph, steps=args.steps,
                    seed=seed, low_level=args.low_level, overrides=args.set or [], init_from=args.init_from,
                    transfer=args.transfer.split(",") if args.transfer is not None else None,
                    restart_schedules=args.restart_schedules, checkpoint_steps=args.checkpoint_steps)
    summary = train(cfg, out, resume=args.resume, progress=not args.no_progress, stop_at=args.stop_at)
    print_summary(summary, out)
    return 0


def _train_seeds(args: argparse.Namespace) -> int:
    """``hubsgo train TASK --seeds ...``: the seeds in lockstep, each in its own run folder."""
    from ..experiments.resolved import RunConfig, RunError
    from ..experiments.seeds import seed_folders, train_seeds

    agent = args.agent or "hubsgo"
    if args.seed is not None:
        raise RunError("give either --seed or --seeds")
    for flag, given in (("--stop-at", args.stop_at), ("--init-from", args.init_from),
                        ("--transfer", args.transfer), ("--restart-schedules", args.restart_schedules or None)):
        if given is not None:
            raise RunError(f"{flag} applies to one run; train the seeds one by one with --seed")
    outs = (seed_folders(Path(args.out), args.seeds) if args.out
            else [Path("runs") / f"{args.task}-{agent}-s{seed}" for seed in args.seeds])
    if args.resume:
        from ..experiments.restore import check_resume

        for seed, out in zip(args.seeds, outs):
            check_resume(out, args.task, agent=args.agent, seed=seed, model=args.model, graph=args.graph,
                         low_level=args.low_level, overrides=args.set or [])
    cfg = RunConfig(task=args.task, agent=agent, model=args.model, graph=args.graph, steps=args.steps,
                    low_level=args.low_level, overrides=args.set or [], checkpoint_steps=args.checkpoint_steps)
    summaries = train_seeds(cfg, args.seeds, outs, resume=args.resume, progress=not args.no_progress,
                            workers=args.workers)
    for summary, out in zip(summaries, outs):
        print_summary(summary, out)
    return 0


def cmd_revise(args: argparse.Namespace) -> int:
    from ..experiments.revise import apply_revision
    from ..experiments.run import RunConfig, RunError, train

    run_dir = Path(args.run_dir)
    if args.no_train and args.stop_at is not None:
        raise RunError("--stop-at pauses the training after the revision, and --no-train trains nothing; give one "
                       "of them")
    r = apply_revision(run_dir, args.model, steps=args.steps, train_after=not args.no_train)
    print(f"revision {r['revision']} of {run_dir} at env step {r['env_steps']:,} (episode {r['episode']}): "
          f"{r['spec_before']} -> {r['spec_after']}")
    print(f"  sub-goals dropped: {names(r['subgoals_dropped'])}; added: {names(r['subgoals_added'])}")
    print(f"  edges added: {names(r['edges_added'])}; dropped: {names(r['edges_dropped'])}; "
          f"re-signed: {names(r['edges_resigned'])}; graph {r['graph']}, prior {r['prior']}, "
          f"likelihood {r['likelihood']}, inference {r['inference']}")
    k = r["kept"]
    if r.get("critic_learned", True):
        print(f"  carried over by name: {k['theta']} unary factors, {k['couplings']} couplings, {k['high_outputs']} "
              f"high-level outputs; new: {names(r['new']['subgoals'] + r['new']['edges'])}; the critic's optimiser "
              f"{'is carried over' if r.get('critic_optimizer') == 'carried over' else 'restarts'}")
    else:
        print(f"  the critic had not updated yet, so it starts as the revised spec says (every factor from its prior "
              f"and signs); carried over by name: {k['high_outputs']} high-level outputs")
    print(f"  recorded in {run_dir / 'revisions' / format(r['revision'], '03d')} and {run_dir / 'revisions.csv'}")
    if r.get("finished"):
        read = ("read from the same recent successes" if r.get("outcomes_kept", 1) or not r["subgoals_added"] else
                "read without recent successes: the stored ones do not say whether they achieved the added "
                "sub-goals, so the filter's window starts afresh and the added ones stand where your spec puts them")
        print(f"the run had taken its budget, so it stays finished; {run_dir / 'subgoals.json'} holds the revised "
              f"critic's G*, {read}; to train on: hubsgo train {_run_task(run_dir)} --out {run_dir} --resume "
              f"--steps TOTAL")
        print(format_ranking(json.loads((run_dir / "subgoals.json").read_text())))
        return 0
    if args.no_train:
        print(f"continue with: hubsgo train {_run_task(run_dir)} --out {run_dir} --resume")
        return 0
    summary = train(RunConfig(task=_run_task(run_dir)), run_dir, resume=True, progress=not args.no_progress,
                    stop_at=args.stop_at)
    print_summary(summary, run_dir)
    return 0


def _run_task(run_dir: Path) -> str:
    from ..experiments.run import run_config

    return str(run_config(run_dir)["task_ref"])
