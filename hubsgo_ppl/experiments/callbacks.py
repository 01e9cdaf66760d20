"""Callbacks of the training driver (:func:`~hubsgo_ppl.experiments.driver.train`), after Stable-Baselines3's
``BaseCallback`` and ``CallbackList``.

The driver plays the agent's training chunks (one episode each for the hierarchical agents), logs each
episode to ``metrics.csv`` and TensorBoard, and calls the hooks of its callbacks, in the order of the
list, at these points::

    on_training_start(run)        once, the run built (or restored) and its log files open
    on_chunk_start(run)           before each chunk; False: stop before playing it
    on_episode(run, stats)        after each training episode is logged; False: stop after this chunk
    on_chunk_end(run)             after each chunk; False: stop here
    on_training_end(run)          once, when the loop ends without an error (budget, pause, a stop)
    on_close(run)                 always, last (after an error too): release what the callback holds

``run`` is the :class:`TrainingRun` (the folder, the typed :class:`ResolvedRun`, the env, the agent,
the logger, the summary ``train`` returns); ``stats`` an :class:`~hubsgo_ppl.agents.episode.EpisodeStats`.
A hook that returns ``False`` (or calls ``run.request_stop()``) ends training at the end of the
current chunk, as a pause: the final checkpoint is written and ``--resume`` continues the run.
Checkpointing, the critic's history, the progress bar, ``stop_at``, the settling summary and G* are
callbacks too; a user's own run after them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

from .checkpoint import g_star_table, save_checkpoint
from .io import write_json
from .logger import CSVOutput, Logger
from .resolved import ResolvedRun

__all__ = ["Callback", "CallbackList", "TrainingRun", "CheckpointCallback", "CriticHistoryCallback",
           "ProgressBarCallback", "StopAtCallback", "MaxEpisodesCallback", "EpisodeFunctionCallback",
           "SettlingCallback", "GStarCallback", "LearningCurveCallback"]


@dataclass
class TrainingRun:
    """What the hooks see: the run being trained."""

    out: Path                       # the run folder
    config: ResolvedRun
    env: Any
    agent: Any                      # the Trainer (agents/protocols.py)
    logger: Logger
    wall0: float = 0.0              # wall time of the run before this call (a resumed run's)
    episodes_this_call: int = 0
    summary: dict[str, Any] = field(default_factory=dict)     # what train returns; callbacks add to it
    g_star: dict[str, Any] | None = None                      # subgoals.json's table, once written
    stop_requested: bool = False
    _t0: float = field(default_factory=time.perf_counter)

    @property
    def total_steps(self) -> int:
        return self.config.steps

    @property
    def has_critic(self) -> bool:
        from ..agents.filters import CriticFilter
        from ..agents.loop import HRLLoop

        return isinstance(self.agent, HRLLoop) and isinstance(self.agent.filter, CriticFilter)

    @property
    def finished(self) -> bool:
        return self.agent.env_steps >= self.total_steps

    def wall_time(self) -> float:
        """Seconds of training of the whole run so far."""
        return self.wall0 + time.perf_counter() - self._t0

    def request_stop(self) -> None:
        """End training at the end of the current chunk (a pause: ``--resume`` continues)."""
        self.stop_requested = True


class Callback:
    """A callback of the training driver; override the hooks you need (each does nothing here)."""

    def on_training_start(self, run: TrainingRun) -> None:
        pass

    def on_chunk_start(self, run: TrainingRun) -> bool | None:
        return None

    def on_episode(self, run: TrainingRun, stats: Any) -> bool | None:
        return None

    def on_chunk_end(self, run: TrainingRun) -> bool | None:
        return None

    def on_training_end(self, run: TrainingRun) -> None:
        pass

    def on_close(self, run: TrainingRun) -> None:
        pass


class CallbackList(Callback):
    """Calls each hook of ``callbacks`` in order; a stopping hook (``False``) stops the run, the others
    of that hook still being called."""

    def __init__(self, callbacks: Iterable[Callback]):
        self.callbacks = list(callbacks)

    def _all(self, hook: str, run: TrainingRun, *args: Any) -> bool:
        go = True
        for cb in self.callbacks:
            if getattr(cb, hook)(run, *args) is False:
                go = False
        if not go:
            run.request_stop()
        return not run.stop_requested

    def on_training_start(self, run: TrainingRun) -> None:
        for cb in self.callbacks:
            cb.on_training_start(run)

    def on_chunk_start(self, run: TrainingRun) -> bool:
        return self._all("on_chunk_start", run)

    def on_episode(self, run: TrainingRun, stats: Any) -> bool:
        return self._all("on_episode", run, stats)

    def on_chunk_end(self, run: TrainingRun) -> bool:
        return self._all("on_chunk_end", run)

    def on_training_end(self, run: TrainingRun) -> None:
        for cb in self.callbacks:
            cb.on_training_end(run)

    def on_close(self, run: TrainingRun) -> None:
        """Every callback's ``on_close``, even if one fails (the first failure is raised afterwards)."""
        error: BaseException | None = None
        for cb in reversed(self.callbacks):
            try:
                cb.on_close(run)
            except Exception as exc:  # noqa: BLE001 - re-raised below, after the others
                error = error or exc
        if error is not None:
            raise error


class CheckpointCallback(Callback):
    """``checkpoint.pt`` at the end of the chunk that crosses each multiple of the run's
    ``checkpoint_steps`` env steps, and at the end of training."""

    def on_training_start(self, run: TrainingRun) -> None:
        self.last = run.agent.env_steps // run.config.checkpoint_steps

    def on_chunk_end(self, run: TrainingRun) -> None:
        if run.agent.env_steps // run.config.checkpoint_steps > self.last:
            self.last = run.agent.env_steps // run.config.checkpoint_steps
            save_checkpoint(run.out, run.config, run.agent, run.wall_time())

    def on_training_end(self, run: TrainingRun) -> None:
        save_checkpoint(run.out, run.config, run.agent, run.wall_time())


class CriticHistoryCallback(Callback):
    """``critic_history.csv``: the training critic's P(w_i = 1) every ``history_every`` episodes (rows
    ``critic=training``), and, once the run ends with G* read, the marginals of the critic G* is read
    from, in a last row numbered one past the last episode: ``critic=settled`` where the agent settled
    and G* comes from the critic refitted on the recent successes (``HRLLoop.g_star_critic``), else
    ``critic=final`` (the training critic at the end). ``subgoals``, ``review`` and ``diagnose`` print
    the marginals of that last row."""

    def on_training_start(self, run: TrainingRun) -> None:
        self.active = run.has_critic
        self.names = list(run.env.unwrapped.subgoal_names)
        self.history = CSVOutput(run.out / "critic_history.csv")

    def _write(self, episode: int, env_steps: int, critic: str, marginals: Iterable[float]) -> None:
        self.history.write({"episode": episode, "env_steps": env_steps, "critic": critic,
                            **{n: round(float(m), 5) for n, m in zip(self.names, marginals)}}, step=env_steps)

    def on_episode(self, run: TrainingRun, stats: Any) -> None:
        if self.active and stats.episode % run.config.history_every == 0:
            self._write(stats.episode, stats.env_steps, "training", run.agent.filter.marginals())

    def on_training_end(self, run: TrainingRun) -> None:
        if self.active and run.g_star is not None:
            settled = run.agent.settled_step is not None
            self._write(run.agent.episodes, run.agent.env_steps, "settled" if settled else "final",
                        [run.g_star["marginals"][n] for n in self.names])


class ProgressBarCallback(Callback):
    """A tqdm bar over the env-step budget. Its fields, over the last 20 episodes: ``return`` (mean
    episode return), ``success`` (success rate); of the last episode: ``p_filter`` (the filter
    probability: the probability that the high level chooses its next sub-goal from Ĝt, the critic's
    sampled set, instead of from every open sub-goal; it rises over training), ``critic_loss`` (the critic's loss in its last updates; HUBS-GO only)."""

    def __init__(self, window: int = 20):
        self.window = window
        self.bar: Any = None

    def on_training_start(self, run: TrainingRun) -> None:
        from tqdm.auto import tqdm

        cfg = run.config
        self.recent: list[tuple[float, float]] = []
        self.last: Any = None
        self.before = run.agent.env_steps
        self.bar = tqdm(total=cfg.steps, initial=min(run.agent.env_steps, cfg.steps), unit="step",
                        dynamic_ncols=True, desc=f"{cfg.agent}/{cfg.task}/s{cfg.seed}")

    def on_chunk_start(self, run: TrainingRun) -> None:
        self.before = run.agent.env_steps

    def on_episode(self, run: TrainingRun, stats: Any) -> None:
        self.recent = (self.recent + [(stats.ret, float(stats.success))])[-self.window:]
        self.last = stats

    def on_chunk_end(self, run: TrainingRun) -> None:
        if not self.recent:
            return
        total = run.total_steps
        self.bar.update(min(run.agent.env_steps, total) - min(self.before, total))
        post = {"return": f"{np.mean([r for r, _ in self.recent]):.2f}",
                "success": f"{np.mean([s for _, s in self.recent]):.2f}",
                "p_filter": f"{self.last.filter_eps:.2f}"}
        if "critic/loss" in self.last.scalars:
            post["critic_loss"] = f"{self.last.scalars['critic/loss']:.3g}"
        self.bar.set_postfix(post, refresh=False)

    def on_close(self, run: TrainingRun) -> None:
        if self.bar is not None:
            self.bar.close()


class StopAtCallback(Callback):
    """Pause once the run reaches env step ``stop_at`` (after the chunk that reaches it)."""

    def __init__(self, stop_at: int):
        self.stop_at = int(stop_at)

    def on_chunk_start(self, run: TrainingRun) -> bool:
        return run.agent.env_steps < self.stop_at


class MaxEpisodesCallback(Callback):
    """Stop after ``max_episodes`` training episodes of this call."""

    def __init__(self, max_episodes: int):
        self.max_episodes = int(max_episodes)

    def on_chunk_start(self, run: TrainingRun) -> bool:
        return run.episodes_this_call < self.max_episodes


class EpisodeFunctionCallback(Callback):
    """Calls ``fn(stats)`` after each training episode (``train``'s ``on_episode``)."""

    def __init__(self, fn: Callable[[Any], Any]):
        self.fn = fn

    def on_episode(self, run: TrainingRun, stats: Any) -> None:
        self.fn(stats)


class LearningCurveCallback(Callback):
    """``learning_curve.png`` at the end of training."""

    def on_training_end(self, run: TrainingRun) -> None:
        from .plots import plot_run_curve

        plot_run_curve(run.out, run.config.to_dict())


class SettlingCallback(Callback):
    """Adds ``settled`` to the summary where the agent settled and G* comes from the settled refit
    (the step, the success rate and window it settled at)."""

    def on_training_end(self, run: TrainingRun) -> None:
        agent = run.agent
        if (run.has_critic and agent.settled_step is not None
                and agent.filter.critic.likelihood.settled_scale() != 1.0):
            run.summary["settled"] = {"step": agent.settled_step, "rate": agent.cfg.settle_at,
                                      "window": agent.cfg.outcome_window}


class GStarCallback(Callback):
    """``subgoals.json``: G*, read from the critic G* comes from, once the run has its whole budget."""

    def on_training_end(self, run: TrainingRun) -> None:
        if run.has_critic and run.finished:
            run.g_star = g_star_table(run.agent, list(run.env.unwrapped.subgoal_names), run.out)
            write_json(run.out / "subgoals.json", run.g_star)


def default_callbacks(stop_at: int | None, max_episodes: int | None, progress: bool,
                      on_episode: Callable[[Any], Any] | None) -> list[Callback]:
    """The harness's own callbacks. Their order matters within a hook: the final checkpoint before
    G*, G* before the history's last row, the history's row of an episode before ``on_episode``."""
    cbs: list[Callback] = [CheckpointCallback(), LearningCurveCallback(), SettlingCallback(), GStarCallback(),
                           CriticHistoryCallback()]
    if progress:
        cbs.append(ProgressBarCallback())
    if stop_at is not None:
        cbs.append(StopAtCallback(stop_at))
    if max_episodes is not None:
        cbs.append(MaxEpisodesCallback(max_episodes))
    if on_episode is not None:
        cbs.append(EpisodeFunctionCallback(on_episode))
    return cbs
