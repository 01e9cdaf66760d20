"""Several seeds of one run trained in one process, in lockstep (``hubsgo train TASK --seeds 0 1 2``).

Each seed is a run of its own: its folder (what ``hubsgo train --seed K`` writes), env, critic, replay
buffers, random streams, log files, checkpoints and callbacks (a :class:`~.driver.RunSession` each).
The seeds' episodes advance one env step at a time together: each seed's HRL loop is a generator
(:meth:`~hubsgo_ppl.agents.loop.HRLLoop.episode_steps`) that stops where its low level must act or
take a gradient step, and the runner serves those requests for every seed at once, with the seeds'
GoalDQN networks stacked (:class:`~hubsgo_ppl.agents.stacked.StackedGoalDQN`): one batched forward for
the greedy actions, one batched TD step for the seeds whose update is due. A seed's high level, critic
and env run as in a run alone.

A seed trained in lockstep gives the files the same seed gives alone, to the bit, on the machines we
measured (docs/benchmarks.md, "Seeds in lockstep"): the batched products give each seed's slice the
floats of its own, and Adam, the clipping and the Polyak step are elementwise per seed. Resume works
per seed, as for a run alone: each folder continues from its own checkpoint, and a seed whose updates
fall on other env steps than the others' after a resume takes them with the seeds it shares them with.

``workers`` > 1 (``hubsgo train TASK --seeds ... --workers 2``) shares the seeds between spawned
processes, each training its share (:func:`shares`) in lockstep.

Agents other than the hierarchical ones with a learned grid low level (``hubsgo``, ``hdqn``) run their
seeds one after another in the process.
"""

from __future__ import annotations

import contextlib
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable, Sequence

import torch

from ..agents.config import HIERARCHICAL
from ..agents.loop import UPDATE_LOW, HRLLoop
from ..agents.low_level import GoalDQN
from .callbacks import default_callbacks
from .driver import RunSession, _interrupted, train
from .lock import run_folder_lock
from .resolved import ResolvedRun, RunConfig, RunError

__all__ = ["train_seeds", "seed_folders", "stacks", "shares"]


def stacks(run: ResolvedRun) -> bool:
    """Whether a sweep trains the seeds of ``run`` in lockstep: the hierarchical agents with the
    minigrid family's learned low level, whose GoalDQN networks stack. The others would run their seeds
    one after another in one process (module docstring), so a sweep gives each of their seeds a worker."""
    return run.agent in HIERARCHICAL and run.low_level == "learned" and run.family == "minigrid"


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
    if len(seeds) == 1:
        return [train(replace(cfg, seed=seeds[0]), outs[0], resume=resumes[0], progress=progress,
                      on_episode=hooks[0])]
    wheres = [{"phase": "start", "task": str(cfg.task)} for _ in seeds]
    try:
        torch.set_num_threads(int(cfg.threads))
        with contextlib.ExitStack() as closing:
            for out in outs:
                closing.enter_context(run_folder_lock(out))
            sessions = [RunSession(replace(cfg, seed=seed), out, again,
                                   default_callbacks(None, None, progress and i == 0, hook), where, closing)
                        for i, (seed, out, again, hook, where) in enumerate(zip(seeds, outs, resumes, hooks, wheres))]
            return _Lockstep(sessions).play()
    except KeyboardInterrupt:
        raise RunError("; ".join(f"seed {s}: {_interrupted(out, w)}" for s, out, w in zip(seeds, outs, wheres))) \
            from None


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
    (an interruption included: :func:`train_seeds` says where each seed stopped)."""
    from ..specs import SpecError
    from .io import CheckpointError

    try:
        conn.send(("ok", train_seeds(cfg, seeds, outs, resumes, progress=progress)))
    except (RunError, CheckpointError, SpecError) as exc:
        conn.send(("error", " ".join(str(exc).split())))
    except BaseException as exc:  # noqa: BLE001 - reported to the parent as one line
        conn.send(("error", f"seeds {' '.join(map(str, seeds))}: {type(exc).__name__}: {exc}"))
    finally:
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
        raise RunError("; ".join(msg for _, msg in sorted(errors)))
    return summaries


class _Lockstep:
    """Plays the sessions' episodes one env step at a time together."""

    def __init__(self, sessions: list[RunSession]):
        self.sessions = sessions
        self.summaries: list[dict[str, Any] | None] = [None] * len(sessions)
        agents = [s.agent for s in sessions]
        self.stacked = None
        if all(isinstance(a, HRLLoop) and isinstance(a.low, GoalDQN) for a in agents):
            from ..agents.stacked import StackedGoalDQN

            try:
                self.stacked = StackedGoalDQN([a.low for a in agents])
            except ValueError:
                self.stacked = None
        self.pending: dict[int, Any] = {}       # seed index -> the generator's open request
        self.steps: dict[int, Any] = {}         # seed index -> its episode's generator

    def play(self) -> list[dict[str, Any]]:
        if self.stacked is None:
            for k, session in enumerate(self.sessions):
                self._one_by_one(k, session)
            return list(self.summaries)
        for k in range(len(self.sessions)):
            self._next_episode(k)
        while self.pending:
            self._tick()
        return list(self.summaries)

    def _one_by_one(self, k: int, session: RunSession) -> None:
        with session.diverged():
            while session.wants_chunk():
                for stats in session.agent.train_chunk():
                    session.log(stats)
                if not session.chunk_end():
                    break
        self.summaries[k] = session.finish()

    def _next_episode(self, k: int) -> None:
        """Start seed k's next episode, or end the seed (budget spent, or a callback stopped it)."""
        session = self.sessions[k]
        if session.wants_chunk():
            self.steps[k] = session.agent.episode_steps(True, None)
            with session.diverged():
                self.pending[k] = next(self.steps[k])
        else:
            self.steps.pop(k, None)
            self.pending.pop(k, None)
            self.summaries[k] = session.finish()

    def _send(self, k: int, value: Any) -> None:
        session = self.sessions[k]
        with session.diverged():
            try:
                self.pending[k] = self.steps[k].send(value)
                return
            except StopIteration as end:
                session.log(end.value)
            go = session.chunk_end()
        if go:
            self._next_episode(k)
        else:
            self.steps.pop(k, None)
            self.pending.pop(k, None)
            self.summaries[k] = session.finish()

    def _tick(self) -> None:
        """One env step of every seed: their actions (the greedy ones batched), then the low levels'
        gradient steps that fall due, batched."""
        lows = self.stacked.lows
        actions, greedy = {}, {}
        for k, (obs, g, eps) in self.pending.items():
            a = lows[k].random_action(eps)
            if a is None:
                greedy[k] = (obs, g)
            else:
                actions[k] = a
        if greedy:
            actions.update(self.stacked.greedy(greedy))
        for k in sorted(actions):
            self._send(k, actions[k])
        due = sorted(k for k, r in self.pending.items() if r is UPDATE_LOW)
        if due:
            for k, stats in zip(due, self.stacked.update(due)):
                self._send(k, stats)
