"""Where the runs of a sweep execute: in spawned local processes (:func:`local`) or as Ray tasks
(:func:`ray_tasks`). The runs of a grid cell (one task and variant, several seeds) whose networks
stack (``Job.lockstep``) go to a worker together and train in lockstep in its process
(:func:`run_bundle`; ``experiments.lockstep``), split so that every worker has a share where there are
fewer cells than workers; every other run goes to a worker of its own. A worker never raises: it
reports each run's outcome, and the sweep decides about retries."""

from __future__ import annotations

import contextlib

import multiprocessing as mp
import os
import signal
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import RunInterrupted
from ..specs import SpecError
from .io import CheckpointError
from .run import CHECKPOINT, RunConfig, RunError

__all__ = ["Job", "run_job", "run_bundle", "bundles", "local", "ray_tasks", "KILL_ENV"]

#: test-only: a worker whose run id ("task/variant/seedK") equals this variable SIGKILLs itself right
#: after its first checkpoint in that process (a deliberately crashed worker for the resume tests)
KILL_ENV = "HUBSGO_SWEEP_TEST_KILL_AFTER_CHECKPOINT"


@dataclass
class Job:
    """One run of a sweep's grid, as a worker gets it: its id, folder, budget and RunConfig fields."""

    run_id: str                  # "task/variant/seedK"
    out: str
    budget: int
    config: dict[str, Any]       # RunConfig fields
    lockstep: bool = False       # its seeds' networks stack (``lockstep.stacks``): train with them in one process


# -- the worker (runs in a child process, or a Ray task) ----------------------------------------------------


def run_job(job: Job) -> dict[str, Any]:
    """Train (or resume) one run; never raises: returns ``{"ok": bool, "error": str | None, ...}``."""
    return run_bundle([job])[0]


def run_bundle(jobs: list[Job]) -> list[dict[str, Any]]:
    """Train (or resume) runs that differ only in their seed, in lockstep in this process; never
    raises: returns each run's ``{"ok": bool, "error": str | None, ...}`` (an error stops them all)."""
    import torch

    from .seeds import train_seeds

    torch.set_num_threads(1)
    outs = [Path(job.out) for job in jobs]
    # train() resumes from the checkpoint, or starts a folder without one afresh through its own guards:
    # it removes only the files it writes (RUN_FILES) and refuses a folder whose logs outlived a checkpoint
    resume = [(out / CHECKPOINT).is_file() for out in outs]
    hooks = [_kill_hook(job) for job in jobs]
    try:
        summaries = train_seeds(RunConfig(**jobs[0].config), [job.config["seed"] for job in jobs], outs,
                                resume=resume, progress=False, on_episode=hooks)
    except RunInterrupted as exc:   # Ctrl-C, or the sweep that started this worker died: stop them all here
        return [{"ok": False, "refused": True, "error": " ".join(str(exc).split())} for _ in jobs]
    except (RunError, CheckpointError, SpecError) as exc:   # a refusal: the same again on a retry
        if len(jobs) > 1:       # the folder refused is one of them: the others train alone
            return [run_bundle([job])[0] for job in jobs]
        return [{"ok": False, "refused": True, "error": " ".join(str(exc).split())}]
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which decides about retries
        return [{"ok": False, "error": f"{type(exc).__name__}: {exc}".strip(), "trace": traceback.format_exc()}
                for _ in jobs]
    results = []
    for summary, again in zip(summaries, resume):
        ok = bool(summary["finished"])
        results.append({"ok": ok, "error": None if ok else "stopped before its budget", "resumed": again,
                        "env_steps": summary["env_steps"]})
    return results


def _kill_hook(job: Job) -> Any:
    if os.environ.get(KILL_ENV) != job.run_id:
        return None
    ckpt = Path(job.out) / CHECKPOINT
    stamp = ckpt.stat().st_mtime_ns if ckpt.exists() else -1

    def hook(stats: Any) -> None:
        if ckpt.exists() and ckpt.stat().st_mtime_ns != stamp:
            os.kill(os.getpid(), signal.SIGKILL)
    return hook


def bundles(jobs: list[Job], workers: int) -> list[list[Job]]:
    """The jobs grouped by grid cell (the same run but for its seed), in order, where they train in
    lockstep (``Job.lockstep``), and one by one otherwise; the largest groups halved while there are
    fewer groups than ``workers``."""
    groups: dict[str, list[Job]] = {}
    for job in jobs:
        key = repr(({k: v for k, v in job.config.items() if k != "seed"}, job.budget)) if job.lockstep else job.run_id
        groups.setdefault(key, []).append(job)
    out = list(groups.values())
    while len(out) < workers and max(map(len, out), default=1) > 1:
        big = max(range(len(out)), key=lambda i: len(out[i]))
        half = (len(out[big]) + 1) // 2
        out[big:big + 1] = [out[big][:half], out[big][half:]]
    return out


def _child(jobs: list[Job], conn: Any) -> None:
    from .seeds import stop_with_parent

    stop_with_parent()
    results = run_bundle(jobs)
    with contextlib.suppress(BrokenPipeError, EOFError, OSError):   # the parent is gone (Ctrl-C): nobody to tell
        conn.send(results)
    conn.close()


# -- backends -----------------------------------------------------------------------------------------------


def local(jobs: list[Job], workers: int, done: Any) -> None:
    """Run jobs in up to ``workers`` spawned processes, a bundle (:func:`bundles`) each; ``done(job,
    result)`` gets each outcome."""
    from multiprocessing.connection import wait

    ctx = mp.get_context("spawn")
    queue = bundles(jobs, workers)
    live: dict[Any, tuple[list[Job], Any, Any]] = {}
    while queue or live:
        while queue and len(live) < workers:
            group = queue.pop(0)
            recv, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_child, args=(group, send), name=f"sweep:{group[0].run_id}", daemon=False)
            proc.start()
            send.close()
            live[proc.sentinel] = (group, proc, recv)
        for sentinel in wait(list(live)):
            group, proc, recv = live.pop(sentinel)
            result = None
            try:
                if recv.poll():
                    result = recv.recv()
            except (EOFError, OSError):
                result = None
            proc.join()
            recv.close()
            if result is None:
                sig = -proc.exitcode if proc.exitcode and proc.exitcode < 0 else None
                why = f"killed by signal {signal.Signals(sig).name}" if sig else f"exit code {proc.exitcode}"
                result = [{"ok": False, "error": f"worker died ({why})"} for _ in group]
            for job, res in zip(group, result):
                done(job, res)


def ray_tasks(jobs: list[Job], workers: int, done: Any) -> None:
    try:
        import ray
    except ImportError:
        raise RunError('the ray backend needs Ray: pip install "hubsgo-ppl[ray]", or use --backend local') \
            from None
    started = not ray.is_initialized()
    if started:
        ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                 runtime_env={"env_vars": {"OMP_NUM_THREADS": "1"}})
    try:
        # our own retry policy decides about crashed runs, so Ray must not retry on its own
        remote = ray.remote(num_cpus=1, max_retries=0)(run_bundle)
        pending = {remote.remote(group): group for group in bundles(jobs, workers)}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            group = pending.pop(ready[0])
            try:
                result = ray.get(ready[0])
            except Exception as exc:  # a worker that died (e.g. SIGKILL) surfaces here
                result = [{"ok": False, "error": f"worker died ({type(exc).__name__})"} for _ in group]
            for job, res in zip(group, result):
                done(job, res)
    finally:
        if started:
            ray.shutdown()
