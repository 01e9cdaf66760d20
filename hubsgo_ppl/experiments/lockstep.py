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

:func:`~.seeds.train_seeds` checks a request for several seeds and calls :func:`train_lockstep` in
its process, or in each of the worker processes that share the seeds (``--workers``).

Agents other than the hierarchical ones with a learned grid low level (``hubsgo``, ``hdqn``) run their
seeds one after another in the process.
"""

from __future__ import annotations

import contextlib
from dataclasses import replace
from pathlib import Path
from typing import Any, Callable

import torch

from ..agents.config import HIERARCHICAL
from ..agents.loop import UPDATE_LOW, HRLLoop
from ..agents.low_level import GoalDQN
from ..errors import RunInterrupted
from .callbacks import default_callbacks
from .checkpoint import CHECKPOINT
from .driver import RunSession, _interrupted, check_resume_steps, train
from .lock import run_folder_lock
from .resolved import ResolvedRun, RunConfig, RunError

__all__ = ["train_lockstep", "stacks"]


def stacks(run: ResolvedRun) -> bool:
    """Whether a sweep trains the seeds of ``run`` in lockstep: the hierarchical agents with the
    minigrid family's learned low level, whose GoalDQN networks stack. The others would run their seeds
    one after another in one process (module docstring), so a sweep gives each of their seeds a worker."""
    return run.agent in HIERARCHICAL and run.low_level == "learned" and run.family == "minigrid"


def train_lockstep(cfg: RunConfig, seeds: list[int], outs: list[Path], resumes: list[bool], progress: bool,
                   hooks: list[Callable[[Any], Any] | None]) -> list[dict[str, Any]]:
    """Train (or resume) the seeds of ``cfg`` in this process, in lockstep: the in-process part of
    :func:`~.seeds.train_seeds`, which checks the arguments (one folder, resume flag and hook per seed)."""
    if len(seeds) == 1:
        return [train(replace(cfg, seed=seeds[0]), outs[0], resume=resumes[0], progress=progress,
                      on_episode=hooks[0])]
    wheres = [{"phase": "start", "task": str(cfg.task)} for _ in seeds]
    try:
        torch.set_num_threads(int(cfg.threads))
        with contextlib.ExitStack() as closing:
            for out in outs:
                closing.enter_context(run_folder_lock(out))
            for seed, out, again in zip(seeds, outs, resumes):      # every seed's refusal before any log is cut
                if again and (out / CHECKPOINT).is_file():
                    check_resume_steps(replace(cfg, seed=seed), out)
            sessions = [RunSession(replace(cfg, seed=seed), out, again,
                                   default_callbacks(None, None, progress and i == 0, hook), where, closing)
                        for i, (seed, out, again, hook, where) in enumerate(zip(seeds, outs, resumes, hooks, wheres))]
            return _Lockstep(sessions).play()
    except KeyboardInterrupt:
        raise RunInterrupted("; ".join(f"seed {s}: {_interrupted(out, w)}" for s, out, w in zip(seeds, outs, wheres))) \
            from None


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
