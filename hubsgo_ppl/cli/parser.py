"""The command line of ``hubsgo``: every subcommand, its options and their help."""

from __future__ import annotations

import argparse

from . import readouts, sweeps, tasks, training

__all__ = ["build_parser", "UsageError"]


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


#: the help of every RUN_DIR argument
RUN_HELP = "a run directory: the --out folder of `hubsgo train`"


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
    from ..agents.config import AGENTS
    from ..experiments.resolved import CHECKPOINT_STEPS

    p = _Parser(prog="hubsgo", description="HUBS-GO: Bayesian sub-goal optimisation for HRL")
    sub = p.add_subparsers(dest="command", required=True)

    t = sub.add_parser("train", help="train an agent on a task and write a run directory",
                       formatter_class=argparse.RawDescriptionHelpFormatter, epilog=TRAIN_EPILOG)
    t.add_argument("task", help="task name (see `hubsgo tasks`) or a catalogue .yaml")
    t.add_argument("--agent", choices=AGENTS, help="the agent to train (default hubsgo)")
    t.add_argument("--model", help="critic spec: a built-in name (e.g. keydoor-specific) or a .yaml path")
    t.add_argument("--graph", choices=["specific", "fully_connected", "independent"],
                   help="override the spec's graph preset")
    t.add_argument("--steps", type=int, help="environment-step budget (default: per task family)")
    t.add_argument("--seed", type=_seed, help="seed of every random stream of the run, 0 or more (default 0)")
    t.add_argument("--seeds", type=_seed, nargs="+", metavar="SEED",
                   help="train several seeds in one process: hubsgo and hdqn with the learned low level of a task "
                        "with discrete actions (a maze, MiniGrid, an env of your own) in lockstep (their networks "
                        "updated together), other runs (arm tasks, baselines) one seed after another; each seed's "
                        "run goes to OUT/seedK with --out, else to runs/TASK-AGENT-sSEED")
    t.add_argument("--workers", type=int, default=1, metavar="N",
                   help="with --seeds: processes (one CPU each) that share the seeds, each training its share "
                        "as --seeds does (default 1; 5 seeds on 2 workers train as 3 and 2)")
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
                        "review, then `hubsgo revise` or --resume; a step past the budget, or one a resumed run "
                        "has reached, is refused")
    t.add_argument("--init-from", metavar="RUN",
                   help="start from this run's critic, high level and low level, sub-goals matched by name")
    t.add_argument("--transfer", metavar="PARTS",
                   help="with --init-from: which parts, comma-separated from critic,high,low (default: all that apply)")
    t.add_argument("--restart-schedules", action="store_true",
                   help="with --init-from: start the transferred parts' exploration schedules afresh (default: "
                        "where the source run left them)")
    t.add_argument("--no-progress", action="store_true", help="no progress bar")
    t.set_defaults(func=training.cmd_train)

    rv = sub.add_parser("revise", help="continue a HUBS-GO run with a revised critic spec (add or drop sub-goals, "
                                       "add, drop or re-sign edges, change the prior or the likelihood)")
    rv.add_argument("run_dir", help=RUN_HELP)
    rv.add_argument("--model", required=True, help="the revised critic spec (.yaml path or built-in name)")
    rv.add_argument("--steps", type=int, help="total env-step budget to train to (default: the run's)")
    rv.add_argument("--stop-at", type=int, metavar="STEP", help="pause once this env step is reached")
    rv.add_argument("--no-train", action="store_true", help="only revise the checkpoint; continue later with --resume")
    rv.add_argument("--no-progress", action="store_true", help="no progress bar")
    rv.set_defaults(func=training.cmd_revise)

    e = sub.add_parser("evaluate", help="greedy return and success rate of a trained run")
    e.add_argument("run_dir", help=RUN_HELP)
    e.add_argument("--episodes", type=int, default=10, help="greedy episodes evaluated (default 10)")
    e.add_argument("--seed", type=_seed, default=None, help="evaluation seed (default: derived from the run's)")
    e.add_argument("--no-break-cycles", action="store_true",
                   help="evaluate the bare greedy low level; by default a step in a state where it already "
                        "acted greedily for the same sub-goal in the episode is random, as in training")
    e.set_defaults(func=readouts.cmd_evaluate)

    s = sub.add_parser("subgoals", help="print the learned sub-goal sets G* of a HUBS-GO run")
    s.add_argument("run_dir", help=RUN_HELP)
    s.add_argument("--samples", type=int, metavar="N",
                   help="recompute G* from the checkpoint with N critic samples (default: the run's subgoals.json, "
                        "else 10,000)")
    s.add_argument("--recompute", action="store_true", help="recompute from the checkpoint")
    s.set_defaults(func=readouts.cmd_subgoals)

    d = sub.add_parser("diagnose", help="ArviZ summary, trace/forest/posterior plots, MRF graph, netCDF")
    d.add_argument("run_dir", help=RUN_HELP)
    d.add_argument("--chains", type=int, default=4, metavar="K",
                   help="independent MH chains drawn from the critic's q(w), at least 2 for r_hat across chains (default 4)")
    d.add_argument("--draws", type=int, default=2000, metavar="N",
                   help="samples kept per chain, after the burn-in (default 2,000)")
    d.add_argument("--burn-in", type=int, default=256, metavar="N",
                   help="MH sweeps per chain discarded before the draws are kept (default 256)")
    d.add_argument("--out", help="folder of the summary, plots and netCDF (default RUN_DIR/diagnostics)")
    d.set_defaults(func=readouts.cmd_diagnose)

    w = sub.add_parser("sweep", help="run a grid of tasks x agents x variants x seeds (resumable)")
    w.add_argument("sweep", help="sweep grid .yaml (e.g. sweeps/quick.yaml) or a built-in sweep name")
    w.add_argument("--backend", choices=["local", "ray"], default="local",
                   help="local worker processes, or a Ray cluster (the ray extra; default local)")
    w.add_argument("--workers", type=int, default=2, help="runs at a time, one CPU each (default 2)")
    w.add_argument("--out", help="sweep directory (default runs/sweeps/NAME)")
    w.add_argument("--variants", nargs="+", metavar="NAME", help="run only these variants (rows) of the grid")
    w.add_argument("--tasks", nargs="+", metavar="NAME", help="run only these tasks (columns) of the grid")
    w.add_argument("--no-progress", action="store_true", help="no progress bar")
    w.set_defaults(func=sweeps.cmd_sweep)

    r = sub.add_parser("report", help="tables (as the paper's Tables 1-2), learning curves and a CSV")
    r.add_argument("sweep_dir", help="the folder `hubsgo sweep` ran into (runs/sweeps/NAME, or its --out)")
    r.add_argument("--out", help="report folder (default SWEEP_DIR/report)")
    r.add_argument("--sweep", help="report only this grid's tasks, variants and seeds (a sweep .yaml or built-in "
                                   "name), for a folder several sweeps ran into; default: the folder's sweep.yaml")
    r.set_defaults(func=sweeps.cmd_report)

    v = sub.add_parser("review", help="mixed-initiative review of a HUBS-GO run: G*, marginals and their trend, "
                                      "learned couplings against your edge signs, suggested spec changes")
    v.add_argument("run_dir", help=RUN_HELP)
    v.add_argument("--threshold", type=float, default=0.2,
                   help="suggest dropping sub-goals with P(w=1) below this (default 0.2)")
    v.add_argument("--dead-band", type=float, default=0.1,
                   help="couplings with |J| at most this have no sign (neither contradict nor suggest one; "
                        "default 0.1)")
    v.add_argument("--out", help="review folder (default RUN_DIR/review; its review.json is the trend's baseline)")
    v.add_argument("--no-gif", action="store_true", help="skip the greedy-episode GIF (MiniGrid mazes)")
    v.add_argument("--seed", type=_seed, default=None,
                   help="evaluation seed of the GIF's episode (default: derived from the run's)")
    v.add_argument("--samples", type=int, default=10_000, help="critic samples for G* (default 10,000)")
    v.add_argument("--top-k", type=int, default=5, help="sub-goal sets listed (default 5)")
    v.add_argument("--last", type=int, default=20, help="episodes of metrics.csv summarised (default 20)")
    v.set_defaults(func=readouts.cmd_review)

    n = sub.add_parser("render", help="animated GIF of one greedy episode on a MiniGrid maze, sub-goals marked")
    n.add_argument("run_dir", help=RUN_HELP)
    n.add_argument("--out", help="GIF to write (default RUN_DIR/episode.gif)")
    n.add_argument("--seed", type=_seed, default=None, help="evaluation seed (default: derived from the run's)")
    n.add_argument("--tile-size", type=int, default=32, help="pixels per grid cell (default 32)")
    n.add_argument("--fps", type=float, default=6.0, help="frames per second (default 6)")
    n.set_defaults(func=readouts.cmd_render)

    k = sub.add_parser("tasks", help="list the tasks and their sub-goal catalogues; given a task or catalogue, "
                                     "check it (and --model) as `hubsgo train` would, without training")
    k.add_argument("task", nargs="*", help="tasks or catalogue .yaml files to check (default: list every task)")
    k.add_argument("--model", help="a critic spec to check against the tasks given")
    k.set_defaults(func=tasks.cmd_tasks)

    c = sub.add_parser("check-env", help="check that an environment meets the sub-goal contract HUBS-GO trains on "
                                         "(one line per missing part and how to add it; exit 1 if any)")
    c.add_argument("env", help="a task (see `hubsgo tasks`), a catalogue .yaml, or a registered Gymnasium id")
    c.add_argument("--steps", type=int, default=50, help="random steps of each of the two seeded rollouts (default 50)")
    c.add_argument("--seed", type=_seed, default=0, help="seed of the resets and the random actions (default 0)")
    c.set_defaults(func=tasks.cmd_check_env)
    return p
