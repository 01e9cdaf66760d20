"""Sweeps: a grid of tasks × agent variants × seeds, run as independent, resumable runs.

A sweep file (``sweeps/*.yaml``) is validated into :class:`SweepSpec`::

    name: quick
    table: table1                 # the paper's table this grid rebuilds (the report prints its numbers)
    seeds: [0, 1, 2]
    checkpoint_steps: 5000        # env steps between checkpoints, for every run
    overrides: []                 # `--set` overrides applied to every run
    tasks:                        # the table's columns, each with its env-step budget
      - {name: keydoor, steps: 60000}
    variants:                     # the table's rows
      - {name: hubsgo-specific, label: "HUBS-GO (specific correlations)", agent: hubsgo, model: "{task}-specific"}
      - {name: hubsgo-independent, agent: hubsgo, graph: independent}     # the spec with a preset graph
      - {name: hdqn-incorrect, agent: hdqn, task: "{task}_incorrect"}     # Table 2: another env, same column
      - {name: td3, agent: td3, tasks: [stack_cubes]}                       # only some columns

A column may be a user's catalogue (``{name: mazes/lab.yaml, steps: 40000}``); a relative path there, or in
a variant's ``task`` or ``model``, is read from the sweep file's folder when the file is there, else from
the working directory, and the column's folder is the file's stem (``lab``).

Run ``(task, variant, seed)`` writes ``SWEEP_DIR/<task>/<variant>/seed<seed>`` through
:func:`hubsgo_ppl.experiments.run.train`, each in its own worker process (spawned, one torch thread).
Re-running a sweep skips finished runs (checkpoint ``env_steps`` ≥ budget), resumes interrupted ones
from their checkpoint, and retries a crashed run once before reporting it as failed. A run folder is
resumed or started afresh by ``train`` itself, with its guards: only the files ``train`` writes
(``RUN_FILES``) are removed, a folder whose logs show a lost checkpoint is refused, and a refused run
is reported in one line without a retry. A grid whose folders hold runs trained with other settings (a sweep file
edited between calls) is refused before any run starts (:func:`check_recorded`).
A sweep's ``name`` is a plain folder name, so that its
default folder ``runs/sweeps/NAME`` stays under ``runs/sweeps``.
"""

from __future__ import annotations

import re
import time
from collections import Counter
from dataclasses import asdict
from pathlib import Path
from typing import Any, ClassVar, Literal

from pydantic import Field, field_validator, model_validator

from ..resources import sweeps_dir
from ..specs import SpecError, StrictModel, load_yaml, validate_spec
from ..validation import VALUE_CHARS, shorten
from .checkpoint import checkpoint_env_steps
from .io import write_yaml
from .run import CHECKPOINT, CHECKPOINT_STEPS, RunConfig, RunError
from .sweep_workers import KILL_ENV, Job, local, ray_tasks, run_job

__all__ = ["SweepSpec", "TaskEntry", "Variant", "Job", "load_sweep", "plan", "select", "run_sweep", "run_status",
           "column_folder", "anchored", "run_job", "KILL_ENV"]

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def column_folder(name: str) -> str:
    """The folder of a sweep column: a built-in task's name, or a catalogue's file stem (``mazes/lab.yaml``
    -> ``lab``)."""
    p = Path(name)
    return p.stem if p.suffix in (".yaml", ".yml") else name


def anchored(ref: str, base: Path) -> str:
    """A relative catalogue or spec path of a sweep file, as found from the sweep file's folder ``base``
    (absolute), or unchanged when it is not there (then it is read from the working directory)."""
    p = Path(ref)
    if p.suffix in (".yaml", ".yml") and not p.is_absolute() and (base / p).is_file():
        return str((base / p).resolve())
    return ref


class TaskEntry(StrictModel):
    name: str = Field(description="a built-in task name or a catalogue .yaml path (a column of the table)")
    steps: int = Field(gt=0, description="env-step budget of every run on this task")
    overrides: list[str] = Field(default_factory=list, description="`--set` overrides for this task's runs")


class Variant(StrictModel):
    name: str = Field(description="folder name of the variant, e.g. hubsgo-specific")
    label: str | None = Field(default=None, description="row label in the report (default: name)")
    agent: str
    task: str = Field(default="{task}", description="env task of the run; {task} is the column's task")
    model: str | None = Field(default=None, description="critic spec name/path; {task} is substituted")
    graph: str | None = Field(default=None, description="override the spec's graph preset")
    low_level: str | None = None
    steps: int | None = Field(default=None, gt=0, description="override the task's budget")
    overrides: list[str] = Field(default_factory=list)
    tasks: list[str] | None = Field(default=None, description="run only on these columns")

    @field_validator("name")
    @classmethod
    def _name_ok(cls, v: str) -> str:
        if not _NAME.match(v):
            raise ValueError(f"{v!r} is not a folder-safe name; use letters, digits, '-', '_' or '.'")
        return v

    @field_validator("agent")
    @classmethod
    def _agent_ok(cls, v: str) -> str:
        from ..agents.config import AGENTS

        if v not in AGENTS:
            raise ValueError(f"unknown agent {v!r}; use one of: {', '.join(AGENTS)}")
        return v

    @field_validator("task", "model")
    @classmethod
    def _template_ok(cls, v: str | None) -> str | None:
        if v is not None:
            try:
                v.format(task="x")
            except (KeyError, ValueError, IndexError) as exc:
                raise ValueError(f"{v!r}: only {{task}} may be filled in ({type(exc).__name__}: {exc})") from None
        return v

    @field_validator("low_level")
    @classmethod
    def _low_level_ok(cls, v: str | None) -> str | None:
        if v is not None and v not in ("learned", "scripted"):
            raise ValueError(f"unknown low level {v!r}; use learned or scripted")
        return v

    @field_validator("graph")
    @classmethod
    def _graph_ok(cls, v: str | None) -> str | None:
        if v is not None and v not in ("specific", "fully_connected", "independent"):
            raise ValueError(f"unknown graph {v!r}; use specific, fully_connected or independent")
        return v

    @property
    def row(self) -> str:
        return self.label or self.name


class SweepSpec(StrictModel):
    spec_kind: ClassVar[str] = "sweep file"
    spec_example: ClassVar[str] = "sweeps/quick.yaml"

    name: str = Field(description="the sweep's folder name under runs/sweeps (letters, digits, '-', '_', '.')")
    table: Literal["table1", "table2"] | None = None
    seeds: list[int] = Field(min_length=1)
    checkpoint_steps: int = Field(default=CHECKPOINT_STEPS, gt=0)
    overrides: list[str] = Field(default_factory=list)
    tasks: list[TaskEntry] = Field(min_length=1)
    variants: list[Variant] = Field(min_length=1)

    @field_validator("name")
    @classmethod
    def _folder_name_ok(cls, v: str) -> str:
        if not _NAME.match(v):
            raise ValueError(f"{shorten(repr(v), VALUE_CHARS)} is not a plain folder name (no '..', '/' or absolute path: the sweep is "
                             "written to runs/sweeps/NAME); use letters, digits, '-', '_' or '.'")
        return v

    @field_validator("seeds")
    @classmethod
    def _seeds_ok(cls, v: list[int]) -> list[int]:
        if len(set(v)) != len(v) or min(v) < 0:
            raise ValueError("seeds must be distinct non-negative integers, e.g. [0, 1, 2]")
        return v

    @model_validator(mode="after")
    def _grid_ok(self) -> "SweepSpec":
        for what, names in (("tasks", [t.name for t in self.tasks]), ("variants", [v.name for v in self.variants])):
            dup = sorted({n for n in names if names.count(n) > 1})
            if dup:
                raise ValueError(f"{what}: duplicate name(s) {dup}; give every entry its own name")
        folders = [column_folder(t.name) for t in self.tasks]
        dup = sorted({f for f in folders if folders.count(f) > 1})
        if dup:
            raise ValueError(f"tasks: columns {dup} would share a folder (a catalogue's folder is its file's stem); "
                             "rename one of the catalogue files")
        columns = {t.name for t in self.tasks}
        for v in self.variants:
            if v.tasks == []:
                raise ValueError(f"variant {v.name!r}: tasks is empty, so it has no run; leave tasks out to run it "
                                 "on every column, or name some of them")
            bad = sorted(set(v.tasks or []) - columns)
            if bad:
                raise ValueError(f"variant {v.name!r}: tasks {bad} are not columns of this sweep; "
                                 f"use some of {sorted(columns)}")
        return self


def load_sweep(sweep: str | Path) -> tuple[SweepSpec, Path]:
    """Load a sweep file (a path, or the name of a shipped one like ``quick``) and check its tasks exist."""
    path = Path(sweep)
    if not path.suffix:
        candidate = sweeps_dir() / f"{sweep}.yaml"
        if candidate.is_file():
            path = candidate
    if not path.is_file():
        shipped = sorted(p.stem for p in sweeps_dir().glob("*.yaml"))
        raise SpecError(f"{sweep}: no such sweep file; pass a path or one of: {', '.join(shipped)}")
    spec = validate_spec(SweepSpec, load_yaml(path, what=SweepSpec.spec_kind), source=str(path))
    from ..envs import get_task

    base = path.parent
    for i, t in enumerate(spec.tasks):
        try:
            get_task(anchored(t.name, base))
        except SpecError as exc:
            raise SpecError(f"{path}: tasks[{i}].name: {exc}") from None
    for j, v in enumerate(spec.variants):
        for t in spec.tasks:
            if v.tasks is None or t.name in v.tasks:
                try:
                    get_task(anchored(v.task.format(task=t.name), base))
                except (SpecError, KeyError, ValueError, IndexError) as exc:
                    raise SpecError(f"{path}: variants[{j}].task: {v.task!r} for column {t.name!r}: {exc}; "
                                    "use a task name, optionally with {task}") from None
    return spec, path


def plan(spec: SweepSpec, sweep_dir: Path, base: Path | None = None) -> list[Job]:
    """Every run of the grid, in table order (tasks, then variants, then seeds). ``base``: the sweep
    file's folder, from which its relative catalogue and spec paths are read (:func:`anchored`)."""
    def ref(name: str) -> str:
        return anchored(name, base) if base is not None else name

    jobs = []
    for t in spec.tasks:
        for v in spec.variants:
            if v.tasks is not None and t.name not in v.tasks:
                continue
            for seed in spec.seeds:
                budget = v.steps or t.steps
                cfg = RunConfig(task=ref(v.task.format(task=t.name)), agent=v.agent,
                                model=ref(v.model.format(task=t.name)) if v.model else None, graph=v.graph,
                                steps=budget, seed=seed, low_level=v.low_level,
                                checkpoint_steps=spec.checkpoint_steps,
                                overrides=[*spec.overrides, *t.overrides, *v.overrides])
                run_id = f"{column_folder(t.name)}/{v.name}/seed{seed}"
                jobs.append(Job(run_id, str(sweep_dir / run_id), budget, asdict(cfg)))
    return jobs


def check_jobs(jobs: list[Job], path: Path) -> None:
    """Resolve each distinct configuration of the grid (spec, settings, agent, low level) as its run
    would, and refuse the sweep in one line at the first that cannot be, naming its run; mark the jobs
    whose seeds train in lockstep (``Job.lockstep``)."""
    from .lockstep import stacks
    from .run import resolve_run

    seen: dict[str, bool] = {}
    for job in jobs:
        key = repr({k: v for k, v in job.config.items() if k != "seed"})
        if key not in seen:
            try:
                seen[key] = stacks(resolve_run(RunConfig(**job.config)))
            except (SpecError, RunError, ValueError) as exc:
                msg = " ".join(str(exc).split())
                raise SpecError(f"{path}: run {job.run_id} cannot start: {msg}") from None
        job.lockstep = seen[key]


#: run config keys that may differ within a cell, or between a run and its grid: they do not change what it learns
_FREE = ("seed", "versions", "checkpoint_steps", "history_every", "threads")


def _differs(a: Any, b: Any, where: str = "") -> str | None:
    """The first dotted key where two plain configs differ, or None where they are equal."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in [*a, *(k for k in b if k not in a)]:
            found = _differs(a.get(k), b.get(k), f"{where}.{k}" if where else str(k))
            if found:
                return found
        return None
    return None if a == b else where


def _settings(cfg: dict[str, Any]) -> dict[str, Any]:
    """A run's config without what may differ in a cell: the seed, the budget (``--steps`` moves it)."""
    out = {k: v for k, v in cfg.items() if k not in _FREE}
    out["hyper"] = {k: v for k, v in (out.get("hyper") or {}).items() if k != "steps"}
    return out


def settings_key(run_dir: Path) -> str | None:
    """What a run was trained with but for its seed and budget (:func:`_settings`), or None where unreadable."""
    from .checkpoint import read_config_file

    cfg = read_config_file(run_dir)
    return repr(sorted(_settings(cfg).items())) if isinstance(cfg, dict) else None


def split_settings(runs: list[Any]) -> tuple[list[Any], list[Any]]:
    """(runs with their cell's settings, the others): a cell's settings are those most of its runs (``task``,
    ``variant``, ``settings``) record, the first run's on a tie; a run recording none counts as its cell's."""
    counts = Counter((r.task, r.variant, r.settings) for r in runs if r.settings is not None)
    cell: dict[tuple[str, str], str] = {}
    for (t, v, key), _ in counts.most_common():
        cell.setdefault((t, v), key)
    other = [r for r in runs if r.settings is not None and r.settings != cell[(r.task, r.variant)]]
    return [r for r in runs if r not in other], other


def check_recorded(jobs: list[Job], path: Path) -> None:
    """Refuse in one line, before any run starts, a grid whose folders hold runs trained with other settings
    than the grid now gives them (a sweep file edited between calls): a finished run would be skipped and an
    interrupted one resumed as recorded, so a cell would mix two settings. A budget is one of them: the schedules
    run over it, so a run moved to another budget part way would differ from its cell's other runs."""
    from .checkpoint import run_config
    from .run import resolve_run

    wanted: dict[str, dict[str, Any]] = {}
    clash = []
    for job in jobs:
        out = Path(job.out)
        if not (out / CHECKPOINT).is_file() and not (out / "config.yaml").is_file():
            continue
        try:
            cfg = run_config(out)
            have, budget = _settings(cfg), (cfg.get("hyper") or {}).get("steps")
        except (RunError, OSError, ValueError, AttributeError):
            continue            # damaged or missing: train() says so for this run
        key = repr({k: v for k, v in job.config.items() if k != "seed"})
        if key not in wanted:
            wanted[key] = _settings(resolve_run(RunConfig(**job.config)).to_dict())
        where = _differs(have, wanted[key])
        if where:
            clash.append(f"{job.run_id} ({where})")
        elif budget != job.budget:     # its schedules run over its budget: a moved one is another setting
            clash.append(f"{job.run_id} (a budget of {budget:,}, not this grid's {job.budget:,})")
    if clash:
        raise SpecError(f"{path}: {len(clash)} run(s) in {Path(jobs[0].out).parent.parent.parent} were trained with "
                        f"other settings than this grid gives them, so their cells would mix two settings: "
                        f"{', '.join(clash[:3])}{', ...' if len(clash) > 3 else ''}; restore the sweep file as it was, "
                        "or run the edited grid into another --out")


def run_status(job: Job) -> str:
    """``"finished"`` (checkpoint at or past the budget), ``"partial"`` (a checkpoint short of it) or ``"new"``."""
    if not (Path(job.out) / CHECKPOINT).is_file():
        return "new"
    steps = checkpoint_env_steps(job.out)      # None: damaged, which train() reports on resume
    return "finished" if steps is not None and steps >= job.budget else "partial"


def select(spec: SweepSpec, path: Path, variants: list[str] | None = None,
           tasks: list[str] | None = None) -> SweepSpec:
    """The part of the grid with only these variants (rows) and tasks (columns); None keeps them all.
    A name the grid lacks is refused, naming the ones it has."""
    update: dict[str, Any] = {}
    for what, chosen, entries in (("variants", variants, spec.variants), ("tasks", tasks, spec.tasks)):
        if chosen is None:
            continue
        names = [e.name for e in entries]
        unknown = [c for c in chosen if c not in names]
        if unknown:
            raise SpecError(f"{path}: no {what} named {', '.join(map(repr, unknown))}; its {what}: {', '.join(names)}")
        update[what] = [e for e in entries if e.name in chosen]
    return spec.model_copy(update=update)


def run_sweep(sweep: str | Path, backend: str = "local", workers: int = 2, out: str | Path | None = None,
              progress: bool = True, variants: list[str] | None = None,
              tasks: list[str] | None = None) -> dict[str, Any]:
    """Run (or continue) a sweep. Returns ``{sweep_dir, finished, skipped, retried, failed, runs}``.
    ``variants`` and ``tasks`` run only those rows and columns of the grid (:func:`select`); the
    folder's ``sweep.yaml`` still records the whole grid, so a later call can run the rest into it.

    ``finished`` counts runs completed by this call, ``skipped`` runs that were already complete,
    ``retried`` runs that crashed once and were run again, ``failed`` the ``"run_id: error"`` of runs
    that crashed twice, or ``"run_id: refused: why"`` of runs whose folder ``train`` refused (not
    retried). ``runs`` maps every run id to its final status.
    """
    if backend not in ("local", "ray"):
        raise RunError(f"unknown backend {backend!r}; use 'local' or 'ray'")
    if workers < 1:
        raise RunError(f"--workers must be at least 1, got {workers}")
    spec, path = load_sweep(sweep)
    part = select(spec, path, variants, tasks)
    sweep_dir = Path(out) if out is not None else Path("runs") / "sweeps" / spec.name
    jobs = plan(part, sweep_dir, base=path.parent)
    if not jobs:
        raise SpecError(f"{path}: no run left: the variants {', '.join(v.name for v in part.variants)} run on none "
                        f"of the tasks {', '.join(t.name for t in part.tasks)}; choose rows and columns that meet")
    check_jobs(jobs, path)           # a misspelled spec or setting stops the sweep before any run starts
    check_recorded(jobs, path)       # an edited grid stops it too, rather than mix two settings in a cell
    sweep_dir.mkdir(parents=True, exist_ok=True)
    write_yaml(sweep_dir / "sweep.yaml", {**spec.model_dump(mode="json"), "source": str(path)})
    status = {j.run_id: run_status(j) for j in jobs}
    todo = [j for j in jobs if status[j.run_id] != "finished"]
    result: dict[str, Any] = {"sweep_dir": str(sweep_dir), "finished": 0,
                              "skipped": len(jobs) - len(todo), "retried": 0, "failed": [],
                              "runs": {j.run_id: ("skipped" if status[j.run_id] == "finished" else None) for j in jobs}}
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(jobs), initial=result["skipped"], unit="run", desc=f"sweep {spec.name}",
                   dynamic_ncols=True)
    execute = local if backend == "local" else ray_tasks
    t0 = time.perf_counter()

    def first(job: Job, res: dict[str, Any]) -> None:
        if res["ok"]:
            result["finished"] += 1
            result["runs"][job.run_id] = "finished"
            if bar is not None:
                bar.update(1)
        elif res.get("refused"):
            result["failed"].append(f"{job.run_id}: refused: {res['error']}")
            result["runs"][job.run_id] = "refused"
            if bar is not None:
                bar.update(1)
        else:
            retry.append((job, res["error"]))

    def second(job: Job, res: dict[str, Any]) -> None:
        if res["ok"]:
            result["finished"] += 1
            result["runs"][job.run_id] = "finished after retry"
        else:
            result["failed"].append(f"{job.run_id}: {res['error']} (first attempt: {first_errors[job.run_id]})")
            result["runs"][job.run_id] = "failed"
        if bar is not None:
            bar.update(1)

    retry: list[tuple[Job, str]] = []
    try:
        execute(todo, workers, first)
        first_errors = {j.run_id: e for j, e in retry}
        result["retried"] = len(retry)
        if retry:
            execute([j for j, _ in retry], workers, second)
    finally:
        if bar is not None:
            bar.close()
    result["wall_time"] = round(time.perf_counter() - t0, 1)
    return result
