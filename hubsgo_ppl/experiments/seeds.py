"""Several seeds of one run (``hubsgo train TASK --seeds 0 1 2 --workers 2``): their run folders, and
the worker processes that share them.

:func:`train_seeds` checks the request, then trains the seeds in lockstep in this process
(:mod:`~.lockstep`) or shares them between ``workers`` spawned processes (:func:`shares`), each training
its share in lockstep. This module loads only the standard library and the run's config: a process
that hands its seeds to workers does not import torch, the agents or the critic, which each worker
imports for itself; their start-up is then paid once, in the workers, side by side.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Sequence

from .resolved import RunConfig, RunError

__all__ = ["train_seeds", "seed_folders", "shares", "stop_with_parent"]


def stop_with_parent(interval: float = 1.0) -> None:
    """In a spawned worker (call it from the main thread): once the process that started it has died
    (killed, so it could not stop its workers itself), interrupt this one as Ctrl-C does, so that its
    runs stop where they are, their last checkpoints kept, rather than train on unseen, holding their
    folders' locks. A daemon thread polls the parent's pid and sends SIGUSR1, whose handler raises
    KeyboardInterrupt (SIGINT itself may be ignored: a job started in the background of a shell)."""
    import os
    import signal
    import threading
    import time

    def orphaned(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    signal.signal(signal.SIGUSR1, orphaned)
    parent = os.getppid()

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(interval)
        os.kill(os.getpid(), signal.SIGUSR1)

    threading.Thread(target=watch, name="stop-with-parent", daemon=True).start()


def seed_folders(out: Path, seeds: Sequence[int]) -> list[Path]:
    """The run folder of each seed under ``out``: ``out/seedK``."""
    return [Path(out) / f"seed{s}" for s in seeds]


def train_seeds(cfg: RunConfig, seeds: Sequence[int], outs: Sequence[Path], resume: bool | Sequence[bool] = False,
                progress: bool = True, on_episode: Sequence[Callable[[Any], Any] | None] | None = None,
                workers: int = 1) -> list[dict[str, Any]]:
    """Train (or resume) the run ``cfg`` for each of ``seeds`` into ``outs``, in lockstep where the
    agent allows; returns each seed's summary, as :func:`~.driver.train` does. ``resume``: one flag for
    every seed, or one per seed; ``on_episode``: a function per seed called after each of its episodes;
    ``workers``: processes (one CPU each) that share the seeds, each training its share in lockstep."""
    seeds, outs = [int(s) for s in seeds], [Path(o) for o in outs]
    resumes = [bool(resume)] * len(seeds) if isinstance(resume, bool) else [bool(r) for r in resume]
    hooks = list(on_episode) if on_episode is not None else [None] * len(seeds)
    if len(set(seeds)) != len(seeds):
        raise RunError(f"--seeds lists a seed twice: {' '.join(map(str, seeds))}")
    if len(outs) != len(seeds) or len(set(outs)) != len(outs):
        raise RunError("each seed needs a run folder of its own")
    if workers < 1:
        raise RunError(f"--workers must be 1 or more, got {workers}")
    if workers > 1 and len(seeds) > 1:
        if any(h is not None for h in hooks):
            raise RunError("per-seed episode hooks run in this process; train with workers=1")
        return _in_workers(cfg, seeds, outs, resumes, progress, workers)
    from .lockstep import train_lockstep    # here, not above: a process that only spawns workers skips it

    return train_lockstep(cfg, seeds, outs, resumes, progress, hooks)


def shares(n: int, workers: int) -> list[range]:
    """The seeds' indices each of ``workers`` processes trains: consecutive runs of them, the largest
    share halved while there are fewer shares than workers (5 seeds on 2 workers: 3 and 2)."""
    out = [range(n)]
    while len(out) < workers and max(map(len, out)) > 1:
        big = max(range(len(out)), key=lambda i: len(out[i]))
        r = out[big]
        half = (len(r) + 1) // 2
        out[big:big + 1] = [r[:half], r[half:]]
    return out


def _share_child(cfg: RunConfig, seeds: list[int], outs: list[Path], resumes: list[bool], progress: bool,
                 conn: Any) -> None:
    """A worker: its share of the seeds in lockstep; sends back their summaries or the one-line error
    (an interruption included: the lockstep runner says where each seed stopped)."""
    from ..errors import CheckpointError
    from ..specs import SpecError

    import contextlib

    stop_with_parent()
    try:
        answer = ("ok", train_seeds(cfg, seeds, outs, resumes, progress=progress))
    except (RunError, CheckpointError, SpecError) as exc:
        answer = ("error", " ".join(str(exc).split()))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent as one line
        answer = ("error", f"seeds {' '.join(map(str, seeds))}: {type(exc).__name__}: {exc}")
    with contextlib.suppress(BrokenPipeError, EOFError, OSError):   # the parent is gone (Ctrl-C): nobody to tell
        conn.send(answer)
    conn.close()


def _in_workers(cfg: RunConfig, seeds: list[int], outs: list[Path], resumes: list[bool], progress: bool,
                workers: int) -> list[dict[str, Any]]:
    """:func:`train_seeds` with the seeds shared between ``workers`` spawned processes (:func:`shares`)."""
    import multiprocessing as mp
    from multiprocessing.connection import wait

    ctx = mp.get_context("spawn")
    waiting = {}        # the pipe each worker answers on -> (its seeds' indices, the process)
    for i, idx in enumerate(shares(len(seeds), workers)):
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_share_child, name=f"seeds:{seeds[idx[0]]}",
                           args=(cfg, [seeds[j] for j in idx], [outs[j] for j in idx], [resumes[j] for j in idx],
                                 progress and i == 0, send))
        proc.start()
        send.close()
        waiting[recv] = (idx, proc)
    summaries: list[dict[str, Any] | None] = [None] * len(seeds)
    errors = []
    while waiting:
        try:
            ready = wait(list(waiting))
        except KeyboardInterrupt:       # the workers got it too: each reports where its seeds stopped
            continue
        for recv in ready:
            idx, proc = waiting.pop(recv)
            try:
                kind, value = recv.recv()
            except (EOFError, OSError):
                kind, value = "error", None
            proc.join()
            if value is None:
                value = f"the worker of seeds {' '.join(str(seeds[j]) for j in idx)} died (exit code {proc.exitcode})"
            if kind == "ok":
                for j, summary in zip(idx, value):
                    summaries[j] = summary
            else:
                errors.append((idx[0], value))
    if errors:
        raise RunError("; ".join(dict.fromkeys(msg for _, msg in sorted(errors))))     # a refusal every worker met, once
    return summaries
