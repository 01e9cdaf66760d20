"""One run: the public face of the run harness, and greedy evaluation.

Run directory::

    config.yaml            the resolved run (task, agent, model spec, hyperparameters, seed, versions)
    metrics.csv            one row per training episode
    critic_history.csv     P(w_i = 1) over training (HUBS-GO): rows ``critic=training`` every few episodes,
                           and a last row with the marginals of the critic G* is read from
                           (``critic=settled`` where that is the settled refit, else ``final``)
    tb/                    TensorBoard events
    checkpoint.pt          latest checkpoint, written atomically at the end of the episode that crosses
                           each multiple of ``checkpoint_steps`` env steps (and at the end of the run)
    subgoals.json          G*: the configuration ranking from G_STAR_SAMPLES (10,000) critic samples (HUBS-GO)
    learning_curve.png     return and success over environment steps (revisions marked)
    eval.json              written by ``evaluate``
    revisions.csv          one line per revision of the critic spec (``hubsgo revise``), if any
    revisions/NNN/         spec_before.yaml, spec_after.yaml and revision.json of revision NNN
    .lock                  there while a process writes the run, which holds its lock (``experiments/lock.py``)

The harness is split by concept: ``resolved.py`` (:class:`RunConfig`, the typed :class:`ResolvedRun`),
``resolve.py`` (resolving a run), ``checkpoint.py`` (the checkpoint and config.yaml), ``restore.py``
(building and restoring a run, checking a resume's flags),
``lock.py`` (the run folder lock), ``callbacks.py`` (:class:`Callback` and the harness's callbacks) and
``driver.py`` (:func:`train`). Their public names are importable from here too.

A model spec may list a subset of the task's catalogue: the run then works on the task with only
those sub-goals (``envs/subset.py``; ``subgoals`` in config.yaml names them, absent when all are
candidates). ``init_from`` in config.yaml records a run started from another run's critic, high
level and/or low level (``--init-from``, ``experiments/transfer.py``).
"""

from __future__ import annotations

import contextlib
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..agents.loop import HRLLoop
from ..agents.seeding import EVAL_SEED_OFFSET, episode_seed
from .callbacks import Callback, CallbackList, TrainingRun
from .checkpoint import (CHECKPOINT, CHECKPOINT_FORMAT, EPISODE_LOGS, G_STAR_SAMPLES, RUN_FILES, read_checkpoint,
                         g_star_table, read_config_file, run_config, run_dir_checkpoint, save_checkpoint,
                         subgoal_table)
from .restore import build_run, check_resume, load_run, restore
from .driver import train
from .io import write_json
from .plots import REVISIONS_CSV, plot_run_curve, read_revisions
from .resolve import (catalogue_digest, check_catalogue, note_unlinked_goals, resolve, resolve_run, task_goals,
                      task_ref, warn_goals_left_out)
from .resolved import CHECKPOINT_STEPS, ResolvedRun, RunConfig, RunError

__all__ = ["RunConfig", "ResolvedRun", "RunError", "Callback", "CallbackList", "TrainingRun", "train", "evaluate",
           "load_run", "run_config", "check_resume", "resolve", "resolve_run", "subgoal_table", "g_star_table", "plot_run_curve",
           "read_revisions", "read_config_file", "read_checkpoint", "restore", "run_dir_checkpoint", "task_ref", "task_goals",
           "catalogue_digest", "check_catalogue", "note_unlinked_goals", "warn_goals_left_out", "CHECKPOINT",
           "CHECKPOINT_FORMAT", "CHECKPOINT_STEPS", "G_STAR_SAMPLES", "REVISIONS_CSV", "RUN_FILES", "EPISODE_LOGS"]


def _build(resolved: Any):
    """(env, agent) of a resolved run (plain data or :class:`ResolvedRun`); kept for older callers."""
    return build_run(resolved)


def _save(out: Path, resolved: Any, agent: Any, wall: float) -> None:
    """Write a run's checkpoint; kept for older callers (:func:`save_checkpoint`)."""
    save_checkpoint(Path(out), resolved, agent, wall)


def evaluate(run_dir: str | Path, episodes: int = 10, seed: int | None = None,
             break_cycles: bool | None = None) -> dict[str, Any]:
    """Greedy evaluation (no exploration; HUBS-GO chooses from Ĝt). Writes eval.json.

    A hierarchical agent's low level breaks its cycles as in training (``loop.eval_break_cycles``, on
    by default; ``break_cycles=False`` evaluates the bare greedy policy); eval.json records which."""
    if episodes <= 0:
        raise RunError(f"--episodes must be positive, got {episodes}")
    run_dir = Path(run_dir)
    resolved, env, agent, _ = load_run(run_dir)
    breaking = None
    if isinstance(agent, HRLLoop):
        if break_cycles is not None:
            agent.cfg.eval_break_cycles = bool(break_cycles)
        breaking = agent.eval_breaks_cycles
    with contextlib.closing(env):
        base = int(resolved["seed"]) + EVAL_SEED_OFFSET if seed is None else int(seed)
        rets, succ, lengths, optimal = [], [], [], []
        maze = resolved["family"] == "minigrid" and hasattr(env.unwrapped, "spec_maze")    # an ASCII layout
        if maze:
            from ..envs.minigrid.bfs import optimal_return
        for i in range(episodes):
            if maze:      # BFS from this episode's start state
                env.reset(seed=episode_seed(base, i))
                try:
                    optimal.append(float(optimal_return(env)))
                except RuntimeError:        # too many states to plan exactly: no optimum to compare with
                    maze, optimal = False, []
            stats = agent.run_episode(train=False, seed=episode_seed(base, i))
            rets.append(stats.ret)
            succ.append(float(stats.success))
            lengths.append(stats.length)
    n = len(rets)
    result = {"task": resolved["task"], "agent": resolved["agent"], "episodes": n,
              "mean_return": float(np.mean(rets)),
              "se_return": float(np.std(rets, ddof=1) / math.sqrt(n)) if n > 1 else 0.0,
              "success_rate": float(np.mean(succ)), "mean_length": float(np.mean(lengths)),
              "returns": [float(r) for r in rets]}
    if breaking is not None:
        result["break_cycles"] = breaking
    if optimal:
        opt = float(np.mean(optimal))
        result["optimal_return"] = opt
        result["fraction_of_optimal"] = result["mean_return"] / opt if opt > 0 else float("nan")
    try:
        write_json(run_dir / "eval.json", result)
    except OSError as exc:      # a run folder shared read-only: the result is still returned (and printed)
        print(f"hubsgo: warning: {run_dir / 'eval.json'}: not written ({exc.strerror or exc}); the result is "
              "only printed", file=sys.stderr)
    return result
