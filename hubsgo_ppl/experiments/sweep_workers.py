"""Where the runs of a sweep execute: one run per worker (:func:`run_job`), in spawned local processes
(:func:`local`) or as Ray tasks (:func:`ray_tasks`). A worker never raises: it reports each outcome,
and the sweep decides about retries."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..specs import SpecError
from .io import CheckpointError
from .run import CHECKPOINT, RunConfig, RunError

__all__ = ["Job", "run_job", "local", "ray_tasks", "KILL_ENV"]

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


# -- the worker (runs in a child process, or a Ray task) ----------------------------------------------------


def run_job(job: Job) -> dict[str, Any]:
    """Train (or resume) one run; never raises: returns ``{"ok": bool, "error": str | None, ...}``."""
    import torch

    from .run import train

    torch.set_num_threads(1)
    out = Path(job.out)
    # train() resumes from the checkpoint, or starts a folder without one afresh through its own guards:
    # it removes only the files it writes (RUN_FILES) and refuses a folder whose logs outlived a checkpoint
    resume = (out / CHECKPOINT).is_file()
    hook = None
    if os.environ.get(KILL_ENV) == job.run_id:
        ckpt = out / CHECKPOINT
        stamp = ckpt.stat().st_mtime_ns if ckpt.exists() else -1

        def hook(stats: Any) -> None:
            if ckpt.exists() and ckpt.stat().st_mtime_ns != stamp:
                os.kill(os.getpid(), signal.SIGKILL)
    try:
        summary = train(RunConfig(**job.config), out, resume=resume, progress=False, on_episode=hook)
    except (RunError, CheckpointError, SpecError) as exc:   # a refusal: the same again on a retry
        return {"ok": False, "refused": True, "error": " ".join(str(exc).split())}
    except BaseException as exc:  # noqa: BLE001 - reported to the parent, which decides about retries
        return {"ok": False, "error": f"{type(exc).__name__}: {exc}".strip(), "trace": traceback.format_exc()}
    ok = bool(summary["finished"])
    return {"ok": ok, "error": None if ok else "stopped before its budget", "resumed": resume,
            "env_steps": summary["env_steps"]}


def _child(job: Job, conn: Any) -> None:
    conn.send(run_job(job))
    conn.close()


# -- backends -----------------------------------------------------------------------------------------------


def local(jobs: list[Job], workers: int, done: Any) -> None:
    """Run jobs in up to ``workers`` spawned processes; ``done(job, result)`` gets each outcome."""
    from multiprocessing.connection import wait

    ctx = mp.get_context("spawn")
    queue = list(jobs)
    live: dict[Any, tuple[Job, Any, Any]] = {}
    while queue or live:
        while queue and len(live) < workers:
            job = queue.pop(0)
            recv, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_child, args=(job, send), name=f"sweep:{job.run_id}", daemon=False)
            proc.start()
            send.close()
            live[proc.sentinel] = (job, proc, recv)
        for sentinel in wait(list(live)):
            job, proc, recv = live.pop(sentinel)
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
                result = {"ok": False, "error": f"worker died ({why})"}
            done(job, result)


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
        remote = ray.remote(num_cpus=1, max_retries=0)(run_job)
        pending = {remote.remote(job): job for job in jobs}
        while pending:
            ready, _ = ray.wait(list(pending), num_returns=1)
            job = pending.pop(ready[0])
            try:
                result = ray.get(ready[0])
            except Exception as exc:  # a worker that died (e.g. SIGKILL) surfaces here
                result = {"ok": False, "error": f"worker died ({type(exc).__name__})"}
            done(job, result)
    finally:
        if started:
            ray.shutdown()
