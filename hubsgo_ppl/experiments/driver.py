"""The training driver: :func:`train` starts (or resumes) a run in its locked folder, plays the agent's
training chunks, logs each episode, and calls its callbacks (``experiments/callbacks.py``), as
Stable-Baselines3's ``learn()`` drives a ``CallbackList``.

``--resume`` continues exactly the recorded run or refuses: from the checkpoint, the CSV logs first cut
back to it (a run killed with ``kill -9`` logged past it), so a killed-and-resumed run ends with the
files of an uninterrupted one (TensorBoard hides the events after the checkpoint); before the first
checkpoint, afresh with the settings ``config.yaml`` records. A run that cannot be built leaves no
folder of its own behind. Ctrl-C, a full disk or a damaged file end ``train`` with one line
(:class:`RunError`), the folder as the last checkpoint left it.
"""

from __future__ import annotations

import contextlib
import math
import sys
from pathlib import Path
from typing import Any, Callable, Sequence

import torch

from ..envs import get_task
from ..errors import RunInterrupted
from .callbacks import Callback, CallbackList, TrainingRun, default_callbacks
from .checkpoint import (CHECKPOINT, EPISODE_LOGS, RUN_FILES, check_episode_log, read_checkpoint, read_config_file,
                         recorded_run)
from .restore import build_run, check_resume, restore
from .io import RunFileError, is_temp_file, truncate_csv, write_yaml
from .lock import LOCK_FILE, run_folder_lock
from .logger import CSVOutput, Logger, TensorBoardOutput, read_csv_rows
from .resolve import (check_catalogue, horizon_below_option, is_catalogue, note_unlinked_goals, resolve_run,
                      warn_goals_left_out)
from .resolved import CHECKPOINT_STEPS, ResolvedRun, RunConfig, RunError

__all__ = ["train"]


def train(cfg: RunConfig, out: str | Path, resume: bool = False, progress: bool = True,
          max_episodes: int | None = None, on_episode: Callable[[Any], None] | None = None,
          stop_at: int | None = None, callbacks: Sequence[Callback] = ()) -> dict[str, Any]:
    """Train (or, with ``resume``, continue) a run into the folder ``out``; returns its summary
    (``run_dir``, ``episodes``, ``env_steps``, ``wall_time``, ``finished``, and ``init_from``,
    ``settled`` where they apply).

    ``callbacks``: the user's own :class:`Callback` objects, called after the harness's own. ``stop_at``:
    pause after the episode that reaches this env step (a checkpoint is written; the schedules still run
    over the whole budget), e.g. to review the critic and revise its spec (``hubsgo revise``) before
    continuing with ``resume``. ``max_episodes`` stops after that many episodes of this call;
    ``on_episode(stats)`` is called after each episode. With ``resume``, the run continues as recorded: a
    ``cfg`` field set away from its default (another task, agent, seed, spec, ``overrides``) that would change
    it is refused, as ``hubsgo train --resume`` refuses such flags. The folder is locked while ``train`` runs;
    whatever happens, the env, the progress bar and the log files are closed on return."""
    out = Path(out)
    if stop_at is not None and int(stop_at) <= 0:
        raise RunError(f"--stop-at must be a positive env step, got {stop_at}")
    user = list(callbacks)
    bad = [type(cb).__name__ for cb in user if not isinstance(cb, Callback)]
    if bad:
        raise RunError(f"callbacks must be Callback objects (hubsgo_ppl.experiments.Callback); got {', '.join(bad)}")
    if isinstance(cfg.threads, bool) or not isinstance(cfg.threads, int) or cfg.threads <= 0:
        raise RunError(f"threads must be a positive whole number, got {cfg.threads!r}")
    if resume:      # what cfg sets away from its defaults must be the run's own, as with `hubsgo train --resume`
        check_resume(out, cfg.task, agent=None if cfg.agent == "hubsgo" else cfg.agent, seed=cfg.seed or None,
                     model=cfg.model, graph=cfg.graph, low_level=cfg.low_level, overrides=cfg.overrides,
                     init_from=cfg.init_from)
    where = {"phase": "start", "task": str(cfg.task)}
    try:
        torch.set_num_threads(cfg.threads)     # before anything is built, as in a sweep worker
        with run_folder_lock(out):
            return _train(cfg, out, resume, default_callbacks(stop_at, max_episodes, progress, on_episode) + user,
                          where, stop_at)
    except KeyboardInterrupt:
        raise RunInterrupted(_interrupted(out, where)) from None


def _interrupted(out: Path, where: dict[str, Any]) -> str:
    resume = f"`hubsgo train {where['task']} --out {out} --resume`"
    if where["phase"] == "end":
        return (f"interrupted at the end of the run; {out / CHECKPOINT} holds its final checkpoint; {resume} "
                "writes what the end of the run writes (G*, the learning curve)")
    if (out / CHECKPOINT).is_file():
        return f"interrupted; {out / CHECKPOINT} holds the last checkpoint; continue with {resume}"
    if (out / "config.yaml").is_file():
        return (f"interrupted before the run's first checkpoint; {resume} starts it afresh with the settings "
                f"{out / 'config.yaml'} records")
    return "interrupted before the run started; nothing was written"


def _train(cfg: RunConfig, out: Path, resume: bool, callbacks: list[Callback], where: dict[str, Any],
           stop_at: int | None) -> dict:
    with contextlib.ExitStack() as closing:
        session = RunSession(cfg, out, resume, callbacks, where, closing, stop_at)
        agent = session.agent
        with session.diverged():
            while session.wants_chunk():
                for stats in agent.train_chunk():
                    session.log(stats)
                if not session.chunk_end():
                    break
        return session.finish()


class RunSession:
    """One run folder being trained: the run built (or restored), its logs open and its callbacks
    started; :func:`train` plays its chunks one after another, and a lockstep runner
    (``experiments.lockstep``) plays the episodes of several of them together. ``closing`` closes the
    env, the logs and the callbacks. ``stop_at``: the env step to pause at, checked against the budget."""

    def __init__(self, cfg: RunConfig, out: Path, resume: bool, callbacks: list[Callback], where: dict[str, Any],
                 closing: contextlib.ExitStack, stop_at: int | None = None):
        run, env, agent, wall0, purge = _start(cfg, out, resume, stop_at)
        where["task"] = run.task_ref
        self.out, self.run, self.agent, self.where = out, run, agent, where
        closing.callback(env.close)
        torch.set_num_threads(run.threads)
        self.logger = Logger([CSVOutput(out / "metrics.csv")])
        closing.callback(self.logger.close)
        self.logger.outputs.append(TensorBoardOutput(out / "tb", purge_step=purge))
        self.state = TrainingRun(out=out, config=run, env=env, agent=agent, logger=self.logger, wall0=wall0)
        self.hooks = CallbackList(callbacks)
        closing.callback(self.hooks.on_close, self.state)
        where["phase"] = "train"
        self.hooks.on_training_start(self.state)

    def wants_chunk(self) -> bool:
        """Whether to play another chunk: budget left and no callback stopping before it."""
        return self.agent.env_steps < self.run.steps and self.hooks.on_chunk_start(self.state)

    def log(self, stats: Any) -> None:
        """An episode played: log it and call the episode hooks."""
        self.state.episodes_this_call += 1
        _log_episode(self.logger, stats, self.state.wall_time())
        self.hooks.on_episode(self.state, stats)

    def chunk_end(self) -> bool:
        """A chunk played: call its hooks (checkpoints); False: stop."""
        return bool(self.hooks.on_chunk_end(self.state))

    @contextlib.contextmanager
    def diverged(self):
        """Non-finite statistics end the run with one line saying what the folder holds."""
        try:
            yield
        except FloatingPointError as exc:
            out = self.out
            kept = (f"{out / CHECKPOINT} holds the last checkpoint" if (out / CHECKPOINT).exists()
                    else "it diverged before its first checkpoint")
            raise FloatingPointError(f"{exc} (env step {self.agent.env_steps:,}): training diverged; {kept}; start a "
                                     "new run (another --out) with lower learning rates, e.g. --set high.lr=3e-4 "
                                     "--set low.lr=1e-4") from None

    def finish(self) -> dict[str, Any]:
        """The run's summary, after the end-of-training hooks (the final checkpoint, G*, the curve)."""
        state, agent = self.state, self.agent
        state.summary.update({"run_dir": str(self.out), "episodes": agent.episodes, "env_steps": agent.env_steps,
                              "wall_time": round(state.wall_time(), 2), "finished": state.finished})
        if self.run.init_from:
            state.summary["init_from"] = dict(self.run.init_from)
        self.where["phase"] = "end"
        self.hooks.on_training_end(state)
        return state.summary


def _check_stop_at(stop_at: int | None, budget: int, done: int, out: Path) -> None:
    """Refuse a ``stop_at`` that could not pause the run: past its budget, or at or before the env step
    it has reached."""
    if stop_at is None:
        return
    if int(stop_at) > budget:
        raise RunError(f"--stop-at {stop_at} is past the run's budget of {budget:,} env steps, where it ends anyway; "
                       f"give a step below {budget}, or raise --steps")
    if int(stop_at) <= done:
        raise RunError(f"--stop-at {stop_at}: {out} has already taken {done:,} env steps; give a step above {done} "
                       f"to pause at")


def _start(cfg: RunConfig, out: Path, resume: bool, stop_at: int | None = None
           ) -> tuple[ResolvedRun, Any, Any, float, int | None]:
    """(resolved run, env, agent, wall time so far, TensorBoard purge step) of a new or resumed run."""
    _refuse_links(out)
    _check_writable(out)
    ckpt_path = out / CHECKPOINT
    started = any((out / name).exists() for name in RUN_FILES)
    if started and not ckpt_path.exists():
        _refuse_lost_checkpoint(out)
        _refuse_foreign(out)
    if not started and not ckpt_path.exists():
        _refuse_nested(out)
    if resume and (ckpt_path.exists() or not started):
        return _resume(cfg, out, stop_at)
    if ckpt_path.exists():
        raise RunError(f"{out} already holds a run; continue it with --resume (resume=True from Python) or choose "
                       "another --out")
    recorded = recorded_run(out) if (out / "config.yaml").exists() else None
    if resume:          # stopped before its first checkpoint: afresh, exactly as config.yaml records it
        if recorded is None:
            raise RunError(f"{out}: the run stopped before its first checkpoint, and its config.yaml is missing or "
                           "damaged, so --resume cannot rebuild it; start a new run with another --out")
        if cfg.steps is not None and int(cfg.steps) != recorded.steps:
            raise RunError(f"{out}: the run stopped before its first checkpoint; --resume starts it afresh with the "
                           f"budget config.yaml records ({recorded.steps:,} env steps); drop --steps, or choose "
                           "another --out for a new run")
        if recorded.init_from:
            raise RunError(f"{out}: the run started from {recorded.init_from.get('run')} (--init-from) and stopped "
                           "before its first checkpoint; start it anew with the same command and another --out")
        check_catalogue(recorded)
        _check_stop_at(stop_at, recorded.steps, 0, out)
        return _new(recorded, out, None, started, resumed=True)
    run = resolve_run(cfg)
    _check_stop_at(stop_at, run.steps, 0, out)
    if recorded is not None and not recorded.same_run(run):
        raise RunError(f"{out} holds a run that stopped before its first checkpoint, with other settings "
                       "(config.yaml); continue it with --resume, or choose another --out")
    return _new(run, out, cfg, started, resumed=False)


def check_resume_steps(cfg: RunConfig, out: Path, stop_at: int | None = None) -> dict:
    """Refuse, before anything of the run is changed, a resume its checkpoint cannot take: ``--steps`` it
    has passed, ``--stop-at`` out of range, a log cut short. Returns the checkpoint."""
    ckpt = read_checkpoint(out / CHECKPOINT)
    done, budget = int(ckpt["env_steps"]), int(ckpt["config"]["hyper"]["steps"])
    target = budget if cfg.steps is None else int(cfg.steps)
    if target > done:       # a run with nothing left to train, or a --steps it has passed, is told so below
        _check_stop_at(stop_at, target, done, out)
    check_episode_log(out, int(ckpt["episodes"]))
    if cfg.steps is not None and int(cfg.steps) != budget and int(cfg.steps) <= done:    # refused as it is
        raise RunError(f"{out}: the run has already taken {done:,} env steps; pass --steps above {done} "
                       f"to train on (its budget is {budget:,})")
    return ckpt


def _resume(cfg: RunConfig, out: Path, stop_at: int | None = None):
    ckpt = check_resume_steps(cfg, out, stop_at)
    done, budget = int(ckpt["env_steps"]), int(ckpt["config"]["hyper"]["steps"])
    run, env, agent = restore(out / CHECKPOINT, ckpt, cfg.steps)     # refusals here leave the logs as they are
    try:
        _tidy(out, ())
        for name in EPISODE_LOGS:
            truncate_csv(out / name, "episode", int(ckpt["episodes"]))
    except BaseException:
        env.close()
        raise
    if (cfg.steps is None or int(cfg.steps) == budget) and done >= budget:
        print(f"hubsgo: {out} has finished its budget of {budget:,} env steps; nothing to train (pass --steps "
              f"above {done} to train on)", file=sys.stderr)
    on_disk = recorded_run(out)
    if on_disk is None or on_disk.to_dict() != run.to_dict():   # a new budget, a lost or damaged file
        write_yaml(out / "config.yaml", run.to_dict())
    # TensorBoard hides the interrupted writer's events after the checkpoint's last episode
    return run, env, agent, float(ckpt.get("wall_time", 0.0)), agent.env_steps + 1


def max_steps_below_solution(task_ref: str, max_steps: Any = None) -> str | None:
    """What to say where a maze's ``max_steps`` (``max_steps``: a ``--set env.max_steps``, else the
    catalogue's) truncates every episode before the shortest solution reaches the goal; None otherwise."""
    from ..envs import get_task
    from ..envs.minigrid.bfs import optimal_steps_range
    from ..envs.minigrid.layout import load_maze_spec

    limit = int(max_steps or load_maze_spec(get_task(task_ref).catalogue).max_steps)
    try:
        low, _ = optimal_steps_range(task_ref)
    except RuntimeError:        # too many states to find the shortest solution: nothing certain to say
        return None
    if limit >= low:
        return None
    return (f"max_steps {limit} is below the shortest solution ({low} steps), so no episode can reach the goal; "
            f"raise options.max_steps (or --set env.max_steps) to {low} or more")


def _new(run: ResolvedRun, out: Path, cfg: RunConfig | None, started: bool, resumed: bool):
    """A run started afresh (``cfg``: the user's request, for --init-from and --set; None on a resume)."""
    from ..envs.minigrid.registered import is_registered

    if run.family == "minigrid" and is_catalogue(run.task_ref) and not resumed and not is_registered(run.task_ref):
        from ..envs.minigrid.bfs import check_reachable

        never = check_reachable(run.task_ref)     # a maze whose goal cannot be reached: SpecError
        if never is None:
            print(f"hubsgo: note: {cfg.task}: the maze has too many states to check exactly before training that its "
                  "goal and sub-goals can be reached; a coarser check over its cells found nothing wrong",
                  file=sys.stderr)
        elif never:
            print(f"hubsgo: warning: {cfg.task}: no state the agent can reach achieves {', '.join(never)}; "
                  "check the layout (a key behind its own door, a walled-in cell, a cell on lava)", file=sys.stderr)
        if never is not None:
            short = max_steps_below_solution(run.task_ref, (run.hyper.get("env") or {}).get("max_steps"))
            if short:
                print(f"hubsgo: warning: {cfg.task}: {short}", file=sys.stderr)
    if not resumed and (short := horizon_below_option(run)):
        print(f"hubsgo: warning: {cfg.task if cfg else run.task}: {short}", file=sys.stderr)
    # a scene of one's own, or a shipped one changed by --set env.KEY (the shipped scenes as they are have none)
    changed = cfg is not None and any(o.split("=", 1)[0].strip().startswith("env.") for o in cfg.overrides)
    own = is_catalogue(run.task_ref) and not get_task(run.task_ref).shipped
    if run.family == "robosuite" and not resumed and (own or changed):
        from ..envs import make
        from ..envs.check import scene_warnings

        env = make(run.task_ref, **run.section("env"))      # a scene of its own, so training's starts untouched
        try:
            for warning in scene_warnings(env, run.seed):
                print(f"hubsgo: warning: {cfg.task if cfg else run.task}: {warning}", file=sys.stderr)
        finally:
            env.close()
    if not resumed:
        note_unlinked_goals(run)
    plan = schedules = None
    if cfg is not None and cfg.init_from is not None:       # every refusal before anything is written
        from ..agents.config import set_keys
        from .transfer import TransferError, continued_schedules, plan_transfer

        plain = run.to_dict()
        try:
            plan = plan_transfer(plain, cfg.init_from, cfg.transfer)
        except TransferError as exc:
            raise RunError(str(exc)) from None
        user_set = set_keys(cfg.overrides, "loop")
        schedules = {} if cfg.restart_schedules else continued_schedules(plan, keep=user_set)
        plain["hyper"].setdefault("loop", {}).update(schedules)
        run = ResolvedRun.from_dict(plain)
    kept = ("config.yaml",) if resumed else ()
    removed = _tidy(out, tuple(n for n in RUN_FILES if n not in kept))
    if removed:
        how = "with the settings config.yaml records" if resumed else ""
        print(f"hubsgo: {out} has no checkpoint (its run stopped before the first one); removed its partial "
              f"files ({', '.join(removed)}) and started the run afresh {how}".rstrip(), file=sys.stderr)
    if run.subgoals and not resumed:
        left = [n for n in get_task(run.task_ref).catalogue.names if n not in run.subgoals]
        print(f"hubsgo: model spec {run.model!r} lists {len(run.subgoals)} of the sub-goals of task "
              f"{run.task!r}; not candidates in this run: {', '.join(left)}", file=sys.stderr)
        warn_goals_left_out(run.model, run.task_ref, list(run.subgoals))
    try:
        env, agent = build_run(run)
    except BaseException as exc:
        if cfg is None or not cfg.overrides or not isinstance(exc, (TypeError, ValueError)):
            raise
        msg = " ".join(str(exc).split())
        raise RunError(f"the run cannot be built with --set {' --set '.join(cfg.overrides)}: {msg}") from None
    try:
        if plan is not None:
            from .transfer import TransferError, apply_transfer

            try:
                init = {**apply_transfer(agent, plan), "schedules": schedules}
            except TransferError as exc:
                raise RunError(str(exc)) from None
            run = run.replace(init_from=init)
        write_yaml(out / "config.yaml", run.to_dict())
    except BaseException:
        env.close()
        raise
    return run, env, agent, 0.0, None


def _refuse_links(out: Path) -> None:
    """The run writes only into its own folder: a symbolic link where one of its files goes is refused."""
    for name in (*RUN_FILES, CHECKPOINT, LOCK_FILE):
        if (out / name).is_symlink():
            raise RunError(f"{out / name}: a symbolic link; a run writes its files only into its own folder, never "
                           "through a link; move the link away (or replace it with the file it points to)")


def _refuse_lost_checkpoint(out: Path) -> None:
    """A run folder without a checkpoint whose logs go past the step of its second one lost it (a run
    killed in the chunk that crosses the first may log past it unsaved): refuse to start that folder
    afresh, which would remove the logs."""
    recorded = read_config_file(out) or {}      # a config.yaml of a run killed while it was written counts too
    try:
        every = max(int(recorded.get("checkpoint_steps", CHECKPOINT_STEPS)), 1)
    except (TypeError, ValueError):
        every = CHECKPOINT_STEPS
    try:
        rows = read_csv_rows(out / "metrics.csv")
        last = max((int(float(r["env_steps"])) for r in rows if r.get("env_steps")), default=0)
    except (RunFileError, KeyError, ValueError):
        last = 0
    if last >= 2 * every:
        raise RunError(f"{out}: {CHECKPOINT} is missing, though metrics.csv reaches env step {last:,}, past the "
                       f"checkpoints every {every:,} steps; put the checkpoint back, or choose another --out")


def _refuse_nested(out: Path) -> None:
    """A new run's folder neither holds runs (a multi-seed run's ``seedK`` folders) nor lies in one: the
    commands that read a folder would take the one run for the other's."""
    def is_run(folder: Path) -> bool:
        return (folder / CHECKPOINT).is_file() or (folder / "config.yaml").is_file()
    inner = sorted(c.name for c in out.iterdir() if c.is_dir() and is_run(c)) if out.is_dir() else []
    if inner:
        raise RunError(f"{out} holds runs of its own ({', '.join(inner[:3])}{', ...' if len(inner) > 3 else ''}); "
                       f"a run trained there would mix its files with theirs; give one of them (--out "
                       f"{out / inner[0]}) or choose another --out")
    if is_run(out.parent):
        raise RunError(f"{out.parent} is a run's folder; a run trained in {out.name}/ inside it would be read as "
                       "part of it; choose another --out")


def _refuse_foreign(out: Path) -> None:
    """A folder without a checkpoint holding a config.yaml or CSV log that no run wrote (a folder of the
    user's own): refuse to start a run there, which would remove them as a killed run's files."""
    cfg = read_config_file(out)
    foreign = ["config.yaml"] if cfg is not None and not cfg.keys() & {"task", "agent", "hyper", "seed",
                                                                       "checkpoint_steps"} else []
    for name in EPISODE_LOGS:       # every log of a run starts with its header, whose first column is episode
        with contextlib.suppress(OSError, UnicodeDecodeError):
            with (out / name).open(encoding="utf-8") as fh:
                first = fh.readline()
            if first.strip() and first.split(",", 1)[0].strip() != "episode":
                foreign.append(name)
    if foreign:
        raise RunError(f"{out}: {', '.join(foreign)} not written by `hubsgo train`, which a new run there would "
                       "replace; move them away, or choose another --out")


def _check_writable(out: Path) -> None:
    try:
        probe = out / ".write-test"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise RunError(f"--out {out}: cannot write there ({exc.strerror}); choose a writable folder") from None


def _tidy(out: Path, names: tuple[str, ...]) -> list[str]:
    """Remove ``names`` (files, or folders of TensorBoard events) from ``out`` and temporary files left
    by interrupted atomic writes of them or of the checkpoint; returns the names removed."""
    removed = [name for name in names if (out / name).exists()]
    for path in (out / name for name in removed):
        if path.is_dir():
            for event in path.glob("events.out.tfevents.*"):
                event.unlink()
            with contextlib.suppress(OSError):
                path.rmdir()            # only if nothing else is in there
        else:
            path.unlink()
    for path in out.iterdir() if out.is_dir() else ():
        if any(is_temp_file(path, target) for target in (*RUN_FILES, CHECKPOINT)) and path.is_file():
            path.unlink()
    return removed


def _log_episode(logger: Logger, stats: Any, wall: float) -> None:
    row = stats.row()
    row["wall_time"] = round(wall, 3)
    for k, v in row.items():
        logger.record(k, v)
    logger.dump(stats.env_steps)
    bad = [k for k, v in stats.scalars.items() if not math.isfinite(float(v))]
    if bad:
        raise FloatingPointError(f"non-finite training statistics {bad} at episode {stats.episode}")
