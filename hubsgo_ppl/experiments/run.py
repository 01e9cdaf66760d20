"""One run: seeds, run directory, metrics, checkpoints, resume, evaluation.

Run directory::

    config.yaml            resolved config (task, agent, model spec, hyperparameters, seed, versions)
    metrics.csv            one row per training episode
    critic_history.csv     P(w_i = 1) over training (HUBS-GO)
    tb/                    TensorBoard events
    checkpoint.pt          latest checkpoint, written atomically at the end of the episode that crosses
                           each multiple of ``checkpoint_steps`` env steps (and at the end of the run)
    subgoals.json          G*: the configuration ranking from G_STAR_SAMPLES (10,000) critic samples (HUBS-GO)
    learning_curve.png     return and success over environment steps (revisions marked)
    eval.json              written by ``evaluate``
    revisions.csv          one line per revision of the critic spec (``hubsgo revise``), if any
    revisions/NNN/         spec_before.yaml, spec_after.yaml and revision.json of revision NNN

A model spec may list a subset of the task's catalogue: the run then works on the task with only
those sub-goals (``envs/subset.py``; ``subgoals`` in config.yaml names them, absent when all are
candidates). ``init_from`` in config.yaml records a run started from another run's critic, high
level and/or low level (``--init-from``, ``experiments/transfer.py``).

``--resume`` continues from the checkpoint: rows that the CSV logs gained after it (a run killed with
``kill -9``) are cut off first, so a killed-and-resumed run ends with the files of an uninterrupted one
(TensorBoard hides the events after the checkpoint). A run that stopped before its first checkpoint is
started afresh; one that cannot be built leaves no folder of its own behind.
"""

from __future__ import annotations

import contextlib
import math
import platform
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from .. import __version__
from ..agents.config import ConfigError, resolve_hyper
from ..agents.factory import build_agent
from ..agents.filters import CriticFilter
from ..agents.loop import HRLLoop
from ..agents.seeding import CRITIC_STREAM, EVAL_SEED_OFFSET, episode_seed, stream_seed
from ..envs import get_task, register
from ..envs.subset import catalogue_order, check_subset, make_subset
from .io import CheckpointError, RunFileError, is_temp_file, load_checkpoint, save_torch, truncate_csv, write_json, write_yaml
from .logger import CSVOutput, Logger, TensorBoardOutput, read_csv_rows
from .plots import plot_learning_curve

__all__ = ["RunConfig", "RunError", "train", "evaluate", "load_run", "subgoal_table", "plot_run_curve",
           "read_revisions", "CHECKPOINT", "CHECKPOINT_STEPS", "REVISIONS_CSV"]

CHECKPOINT = "checkpoint.pt"
#: version of the checkpoint layout (``{"format", "config", "agent", "episodes", "env_steps", "wall_time"}``)
CHECKPOINT_FORMAT = 1
#: env steps between checkpoints. Counted in env steps, not episodes (as Stable-Baselines3's
#: CheckpointCallback does), so that an agent whose episodes get short does not pay for more checkpoints
#: (each holds the replay buffers) than one that still wanders; a kill loses at most this many steps.
CHECKPOINT_STEPS = 5_000
#: critic samples behind G*, the configuration ranking of subgoals.json
G_STAR_SAMPLES = 10_000
#: what ``train`` writes into a run directory besides the checkpoint (``tb`` is a folder)
RUN_FILES = ("config.yaml", "metrics.csv", "critic_history.csv", "tb", "learning_curve.png", "subgoals.json")
#: per-episode logs, cut back to the checkpoint on resume
EPISODE_LOGS = ("metrics.csv", "critic_history.csv")
#: one line per revision of the critic spec (experiments/revise.py writes it; the learning curve marks them)
REVISIONS_CSV = "revisions.csv"


class RunError(RuntimeError):
    """A run cannot start or continue; the message names the cause and the fix."""


@dataclass
class RunConfig:
    task: str
    agent: str = "hubsgo"
    model: str | None = None          # spec name or path; default "<task>-specific"
    graph: str | None = None          # override the spec's graph preset
    steps: int | None = None          # env-step budget; default per task family
    seed: int = 0
    low_level: str | None = None      # "learned" | "scripted"; default per task family
    checkpoint_steps: int = CHECKPOINT_STEPS   # env steps between checkpoints
    history_every: int = 5            # episodes between critic marginal snapshots
    threads: int = 1                  # torch threads (small nets: 1 is fastest and reproducible)
    overrides: list[str] = field(default_factory=list)
    init_from: str | None = None      # a run directory whose critic / high level / low level start this run
    transfer: list[str] | None = None  # which of them ("critic", "high", "low"); default: all that apply
    # with init_from: start the transferred parts' schedules afresh instead of where the source left them
    restart_schedules: bool = False


def _critic_from_config(resolved: dict[str, Any]) -> Any:
    from ..infer.critic import SubgoalCritic
    from ..specs import ModelSpec

    spec = ModelSpec.model_validate(resolved["model_spec"])
    return SubgoalCritic.from_spec(spec, seed=stream_seed(resolved["seed"], CRITIC_STREAM))


def task_ref(task: str | Path) -> str:
    """How a run's config names its task: a built-in name as given, a user's catalogue by its absolute
    path, so that the run can be evaluated, reviewed, revised and resumed from any folder."""
    return str(Path(task).resolve()) if _is_catalogue(task) else str(task)


def _is_catalogue(task: str | Path) -> bool:
    return Path(str(task)).suffix in (".yaml", ".yml")


def catalogue_digest(path: str | Path) -> str:
    """SHA-256 of a user's catalogue and the layout file it names: a run records it, and a run read
    later says so where the files have changed since."""
    import hashlib

    import yaml

    path = Path(path)
    h = hashlib.sha256(path.read_bytes())
    try:
        options = (yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get("options") or {}
    except (UnicodeDecodeError, yaml.YAMLError, AttributeError):
        return h.hexdigest()            # a damaged catalogue: its own bytes say it changed
    layout = options.get("layout") if isinstance(options, dict) else None
    if isinstance(layout, str) and (path.parent / layout).is_file():
        h.update((path.parent / layout).read_bytes())
    return h.hexdigest()


def check_catalogue(resolved: dict[str, Any]) -> bool:
    """Before a run is rebuilt: refuse (one line) a user's catalogue that has gone, and warn (and say
    True) where it has changed since the run recorded it."""
    ref = resolved.get("task_ref", "")
    if not _is_catalogue(ref):
        return False
    if not Path(ref).is_file():
        raise RunError(f"{ref}: the run's task catalogue is no longer there; put it (and its layout) back at that "
                       "path to read or resume the run")
    recorded = resolved.get("task_digest")
    if recorded is not None and catalogue_digest(ref) != recorded:
        print(f"hubsgo: warning: {ref} (or its layout) has changed since the run recorded it; the run is read "
              "with the files as they are now", file=sys.stderr)
        return True
    return False


def resolve(cfg: RunConfig) -> dict[str, Any]:
    """Everything a run needs, as plain data (written to config.yaml and into checkpoints)."""
    info = get_task(cfg.task)
    if cfg.steps is not None and cfg.steps <= 0:
        raise RunError(f"--steps must be positive, got {cfg.steps}")
    if int(cfg.checkpoint_steps) <= 0:
        raise RunError(f"checkpoint_steps must be a positive number of env steps, got {cfg.checkpoint_steps}")
    if isinstance(cfg.seed, bool) or not isinstance(cfg.seed, int) or cfg.seed < 0:
        raise RunError(f"a seed is a whole number, 0 or more; got {cfg.seed!r}")
    budget_set = [o for o in cfg.overrides if o.split("=", 1)[0].strip() == "steps"]
    if cfg.steps is not None and budget_set:
        raise RunError(f"the budget is given twice, --steps {cfg.steps} and --set {budget_set[-1]}; give it once")
    try:        # the preset, the task's settings and --set merged and validated (agents/config.py)
        hyper = resolve_hyper(info.family, info.name, cfg.agent, cfg.overrides, steps=cfg.steps,
                              low_level=cfg.low_level)
    except ValueError as exc:           # a ConfigError always; another ValueError where --set caused it
        if not (cfg.overrides or isinstance(exc, ConfigError)):
            raise
        raise RunError(str(exc)) from None
    ref = task_ref(cfg.task)
    resolved: dict[str, Any] = {
        "task": info.name, "task_ref": ref, "family": info.family,
        **({"task_digest": catalogue_digest(ref)} if _is_catalogue(cfg.task) else {}),
        "agent": cfg.agent, "seed": int(cfg.seed), "hyper": hyper,
        "checkpoint_steps": int(cfg.checkpoint_steps), "history_every": cfg.history_every, "threads": cfg.threads,
        "versions": {"hubsgo_ppl": __version__, "torch": str(torch.__version__), "python": platform.python_version()},
    }
    names = info.catalogue.names
    if cfg.graph is not None and cfg.agent != "hubsgo":
        raise RunError(f"--graph {cfg.graph} sets the critic's graph, and agent {cfg.agent!r} has no critic; "
                       "drop --graph, or train --agent hubsgo")
    if cfg.agent == "hubsgo" or cfg.model is not None:
        from ..specs import SpecError, list_model_specs, load_model_spec, match_subgoals

        model = cfg.model or f"{info.name}-specific"
        missing = cfg.model is None and model not in list_model_specs()
        inherited = None
        if missing and cfg.init_from is not None:
            inherited = _source_spec(cfg.init_from)     # a user's maze started from another run: that run's spec
        if missing and inherited is None:
            raise SpecError(f"task {info.name!r} has no built-in critic spec {model}: write one (its sub-goals, "
                            "your signed edges, the prior and the likelihood; models/keydoor-specific.yaml is an "
                            "example) and pass it with --model my_spec.yaml")
        if inherited is not None:
            spec = inherited if cfg.graph is None else inherited.model_copy(update={"graph": cfg.graph})
            model = spec.name
            print(f"hubsgo: note: no --model: the critic spec of the --init-from run, {spec.name!r}", file=sys.stderr)
        else:
            spec = load_model_spec(model, graph=cfg.graph)
        source = f"model spec {model!r} for task {info.name!r}"
        if set(spec.subgoals) >= set(names):
            spec = match_subgoals(spec, list(names), source)
        else:       # some of the catalogue's sub-goals: the run's candidates are those (envs/subset.py)
            check_subset(spec.subgoals, names, source)
            spec = spec.model_copy(update={"subgoals": catalogue_order(spec.subgoals, names)})
            resolved["subgoals"] = list(spec.subgoals)
        resolved["model_spec"] = spec.model_dump(mode="json")
        resolved["model"] = spec.name
        if cfg.model is None and inherited is None and _is_catalogue(cfg.task):
            print(f"hubsgo: note: no --model: the built-in spec {model!r}, named after the catalogue's task "
                  f"{info.name!r}; pass --model to use your own", file=sys.stderr)
        if spec.task is not None and spec.task != info.name:     # it fits (above); say whose it was
            print(f"hubsgo: note: model spec {spec.name!r} names task {spec.task!r}; it is used for {info.name!r}, "
                  "its sub-goals matched by name", file=sys.stderr)
        if cfg.graph is None and spec.graph == "independent" and spec.edges:
            print(f"hubsgo: note: model spec {spec.name!r} has graph independent, so its edges ({len(spec.edges)}) "
                  "are not used; graph specific uses them", file=sys.stderr)
    return resolved


def _source_spec(run_dir: str | Path) -> Any:
    """The critic spec a run was trained with, or None where it has none."""
    from ..specs import ModelSpec

    try:
        spec = run_config(run_dir).get("model_spec")
    except (RunError, CheckpointError):
        return None             # the transfer's own checks name what is wrong with that run
    return ModelSpec.model_validate(spec) if isinstance(spec, dict) else None


def task_goals(task_ref: str) -> list[str]:
    """The names of the task catalogue's ``goal`` sub-goals."""
    return [d.name for d in get_task(task_ref).catalogue.subgoals if d.kind == "goal"]


def warn_goals_left_out(spec_name: str, task_ref: str, subgoals: list[str] | None) -> None:
    """One warning line when a run's candidate set (a spec's ``subgoals``; None: the whole catalogue)
    leaves out the task's goal: the high level can never choose it, so the agent reaches it only by chance."""
    missing = [g for g in task_goals(task_ref) if g not in subgoals] if subgoals else []
    if missing:
        print(f"hubsgo: warning: model spec {spec_name!r} leaves out {', '.join(missing)} (the task's goal): the high "
              "level can never choose it, so the agent reaches it only by chance; add it to subgoals and link the "
              "last sub-goal of each route to it", file=sys.stderr)


def _unlinked_goals(resolved: dict[str, Any]) -> list[str]:
    """The catalogue's ``goal`` sub-goals that a ``specific`` spec links to nothing by a positive edge,
    where its Ising prior's negative field outweighs what the outcome likelihood makes of a sub-goal
    every success achieves (``OutcomeLikelihood.mismatch_nats``): G* then leaves them out
    (docs/results.md, "How strongly the successes speak")."""
    from ..infer.likelihoods import get_likelihood

    spec = resolved.get("model_spec")
    prior, lik = ((spec or {}).get(k) or {} for k in ("prior", "likelihood"))
    if not spec or spec.get("graph") != "specific" or prior.get("name") != "ising" or lik.get("name") != "outcome":
        return []
    outcome = get_likelihood("outcome", **{k: v for k, v in lik.items() if k != "name"})
    if outcome.mismatch_nats > -float(prior.get("field", 0.0)):
        return []
    linked = {end for u, v, sign in spec.get("edges", []) if sign == "positive" for end in (u, v)}
    return [g for g in task_goals(resolved["task_ref"]) if g in spec["subgoals"] and g not in linked]


def note_unlinked_goals(resolved: dict[str, Any]) -> None:
    """A one-line note on stderr for each run (new or revised) whose spec leaves the goal unlinked."""
    unlinked = _unlinked_goals(resolved)
    if unlinked:
        print(f"hubsgo: note: model spec {resolved['model']!r} gives {', '.join(unlinked)} (the task's goal) no "
              "positive edge, so its prior's field keeps it out of G*; link the last sub-goal of each route "
              "to it (e.g. [a_door, goal, positive])", file=sys.stderr)


def _build(resolved: dict[str, Any]):
    register()
    # built-in name or catalogue path; with a ``subgoals`` subset, the task with only those sub-goals
    env = make_subset(resolved["task_ref"], resolved.get("subgoals"), **resolved["hyper"].get("env", {}))
    try:
        critic = _critic_from_config(resolved) if resolved["agent"] == "hubsgo" else None
        agent = build_agent(resolved["agent"], env, resolved["hyper"], resolved["seed"], critic=critic)
    except BaseException:
        env.close()
        raise
    return env, agent


def read_config_file(out: Path) -> dict[str, Any] | None:
    """``out/config.yaml`` as a mapping, or None where it is missing or damaged."""
    import yaml

    try:
        cfg = yaml.safe_load((out / "config.yaml").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    return cfg if isinstance(cfg, dict) else None


def _refuse_lost_checkpoint(out: Path) -> None:
    """A run folder without a checkpoint whose logs go past the step of its second one lost it (a run
    killed in the chunk that crosses the first may log past it unsaved): refuse to start that folder
    afresh, which would remove the logs."""
    cfg = read_config_file(out) or {}
    every = int(cfg.get("checkpoint_steps", CHECKPOINT_STEPS))
    try:
        rows = read_csv_rows(out / "metrics.csv")
        last = max((int(float(r["env_steps"])) for r in rows if r.get("env_steps")), default=0)
    except (RunFileError, KeyError, ValueError):
        last = 0
    if last >= 2 * every:
        raise RunError(f"{out}: {CHECKPOINT} is missing, though metrics.csv reaches env step {last:,}, past the "
                       f"checkpoints every {every:,} steps; put the checkpoint back, or choose another --out")


def _check_writable(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise RunError(f"--out {out}: a file, not a folder; choose a folder for the run")
    try:
        out.mkdir(parents=True, exist_ok=True)
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


def _save(out: Path, resolved: dict[str, Any], agent: Any, wall: float) -> None:
    save_torch(out / CHECKPOINT, {"format": CHECKPOINT_FORMAT, "config": resolved, "agent": agent.state_dict(),
                                   "episodes": agent.episodes, "env_steps": agent.env_steps, "wall_time": wall})


def _run_checkpoint(path: Path) -> dict[str, Any]:
    ckpt = load_checkpoint(path)
    missing = [k for k in ("config", "agent", "episodes", "env_steps") if k not in ckpt]
    if missing or not isinstance(ckpt["config"], dict):
        raise CheckpointError(f"{path}: not a checkpoint of a `hubsgo train` run (missing {missing or ['config']}); "
                              "point at a run directory written by `hubsgo train`")
    return ckpt


def run_config(run_dir: str | Path) -> dict[str, Any]:
    """A run's resolved config: its ``config.yaml``, or the checkpoint's copy where that file is missing
    or damaged."""
    run_dir = Path(run_dir)
    cfg = read_config_file(run_dir)
    if cfg is not None and {"task", "task_ref", "agent", "seed", "hyper"} <= set(cfg):
        return cfg
    return run_dir_checkpoint(run_dir)["config"]


def run_dir_checkpoint(run_dir: Path) -> dict[str, Any]:
    """The checkpoint of a run directory, with one line where ``run_dir`` is not one."""
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: no such run directory; pass the --out folder of `hubsgo train`")
    if not (run_dir / CHECKPOINT).is_file():
        raise RunError(f"{run_dir}: not a run directory (no {CHECKPOINT}); pass the --out folder of `hubsgo train`, "
                       "after its first checkpoint")
    return _run_checkpoint(run_dir / CHECKPOINT)


def _restore(path: Path, ckpt: dict[str, Any], steps: int | None = None):
    """(env, agent) built from a checkpoint's config with the agent's state loaded; ``steps``: a new budget."""
    resolved = ckpt["config"]
    if steps is not None:
        resolved["hyper"]["steps"] = int(steps)
    changed = check_catalogue(resolved)
    env, agent = _build(resolved)
    try:
        agent.load_state_dict(ckpt["agent"])
    except (KeyError, RuntimeError, ValueError) as exc:
        env.close()
        if changed:
            raise CheckpointError(f"{path}: the run's networks do not fit {resolved['task_ref']} as it is now, which "
                                  "has changed since the run recorded it; put the catalogue and its layout back as "
                                  "they were") from None
        msg = " ".join(str(exc).split())[:300]
        raise CheckpointError(f"{path}: does not match its own config ({msg}); "
                              "the checkpoint is damaged; start a new run") from None
    except BaseException:
        env.close()
        raise
    if steps is not None:       # every Trainer's cfg is a Budget (agents/protocols.py)
        agent.cfg.total_steps = int(steps)
    return env, agent


def load_run(run_dir: str | Path):
    """(resolved config, env, agent, checkpoint) of a run directory, agent restored from its checkpoint."""
    run_dir = Path(run_dir)
    ckpt = run_dir_checkpoint(run_dir)
    env, agent = _restore(run_dir / CHECKPOINT, ckpt)
    return ckpt["config"], env, agent, ckpt


def subgoal_table(critic: Any, names: list[str], num_samples: int = G_STAR_SAMPLES, top_k: int = 5) -> dict[str, Any]:
    ranking = critic.ranking(num_samples=num_samples, top_k=top_k)
    marg = critic.marginals().detach().cpu().numpy().tolist()
    return {"names": names, "num_samples": num_samples, "ranking": ranking,
            "marginals": dict(zip(names, marg)),
            "factors": {"unary": critic.factors()["unary"],
                        "pairwise": {f"{u}--{v}": j for (u, v), j in critic.factors()["pairwise"].items()}}}


def _at(tree: dict[str, Any], path: list[str]) -> Any:
    for key in path:
        if not isinstance(tree, dict) or key not in tree:
            return None
        tree = tree[key]
    return tree


def check_resume(out: str | Path, task: str, *, agent: str | None = None, seed: int | None = None,
                 model: str | None = None, graph: str | None = None, low_level: str | None = None,
                 overrides: Sequence[str] = (), init_from: str | None = None) -> None:
    """Refuse (one line) a ``--resume`` whose other flags would change the run in ``out``: a resumed run
    continues as its checkpoint's config says. Flags equal to the run's own pass, so the command that
    started a run can be repeated with ``--resume``; a flag left out (None) is not compared."""
    out = Path(out)
    if not (out / CHECKPOINT).exists():
        return
    run = run_config(out)       # config.yaml, which matches the checkpoint (else the checkpoint's own copy)
    clash = []
    if task not in (run["task"], run["task_ref"]) and task_ref(task) != run["task_ref"]:
        clash.append(f"task {task} (the run's is {run['task_ref']})")
    if agent is not None and agent != run["agent"]:
        clash.append(f"--agent {agent} (the run's is {run['agent']})")
    if seed is not None and int(seed) != int(run["seed"]):
        clash.append(f"--seed {seed} (the run's is {run['seed']})")
    if low_level is not None and low_level != run["hyper"].get("low_level"):
        clash.append(f"--low-level {low_level} (the run's is {run['hyper'].get('low_level')})")
    ours = run.get("model_spec") or {}
    if model is not None:
        theirs = resolve(RunConfig(task=run["task_ref"], agent="hubsgo", model=model, graph=graph))["model_spec"]
        if theirs != ours:
            clash.append(f"--model {model} (the run's spec is {run.get('model')!r}; revise it with `hubsgo revise`)")
    elif graph is not None and graph != ours.get("graph"):
        clash.append(f"--graph {graph} (the run's is {ours.get('graph')}; revise the spec with `hubsgo revise`)")
    if overrides:
        info = get_task(run["task_ref"])
        try:
            hyper = resolve_hyper(info.family, info.name, run["agent"], list(overrides), steps=run["hyper"]["steps"],
                                  low_level=run["hyper"].get("low_level"))
        except ValueError as exc:
            raise RunError(str(exc)) from None
        for item in overrides:
            path = item.split("=", 1)[0].strip().split(".")
            if _at(hyper, path) != _at(run["hyper"], path):
                clash.append(f"--set {item} (the run's is {_at(run['hyper'], path)!r})")
    if init_from is not None:
        source = (run.get("init_from") or {}).get("run")
        if source is None or Path(source).resolve() != Path(init_from).resolve():
            clash.append(f"--init-from {init_from} (the run {'started from ' + source if source else 'started afresh'})")
    if clash:
        raise RunError(f"{out}: --resume continues the run as its checkpoint records it, and "
                       f"{'; '.join(clash)} would change it; drop those flags, or choose another --out for a new run")


def _start(cfg: RunConfig, out: Path, resume: bool):
    """(resolved config, env, agent, wall time so far, TensorBoard purge step) of a new or resumed run.

    Resuming cuts the per-episode logs back to the checkpoint. A run that stopped before its first
    checkpoint has nothing to resume: its partial files are removed and it starts afresh."""
    ckpt_path = out / CHECKPOINT
    started = any((out / name).exists() for name in RUN_FILES)
    if started and not ckpt_path.exists():
        _refuse_lost_checkpoint(out)
    if resume and (ckpt_path.exists() or not started):
        ckpt = _run_checkpoint(ckpt_path)
        _check_writable(out)
        _tidy(out, ())
        for name in EPISODE_LOGS:
            truncate_csv(out / name, "episode", int(ckpt["episodes"]))
        done, budget = int(ckpt["env_steps"]), int(ckpt["config"]["hyper"]["steps"])
        if cfg.steps is not None and int(cfg.steps) != budget:
            if int(cfg.steps) <= done:
                raise RunError(f"{out}: the run has already taken {done:,} env steps; pass --steps above {done} "
                               f"to train on (its budget is {budget:,})")
        elif done >= budget:
            print(f"hubsgo: {out} has finished its budget of {budget:,} env steps; nothing to train (pass --steps "
                  f"above {done} to train on)", file=sys.stderr)
        on_disk = read_config_file(out)
        env, agent = _restore(ckpt_path, ckpt, cfg.steps)
        if on_disk != ckpt["config"]:       # config.yaml says what the checkpoint says (a new budget, a lost file)
            write_yaml(out / "config.yaml", ckpt["config"])
        # TensorBoard hides the interrupted writer's events after the checkpoint's last episode
        return ckpt["config"], env, agent, float(ckpt.get("wall_time", 0.0)), agent.env_steps + 1
    if ckpt_path.exists():
        raise RunError(f"{out} already holds a run; continue it with --resume or choose another --out")
    resolved = resolve(cfg)
    if resolved["family"] == "minigrid" and _is_catalogue(cfg.task):
        from ..envs.minigrid.bfs import check_reachable

        never = check_reachable(resolved["task_ref"])     # a maze whose goal cannot be reached: SpecError
        if never is None:
            print(f"hubsgo: note: {cfg.task}: the maze has too many states to check exactly before training that its "
                  "goal and sub-goals can be reached; a coarser check over its cells found nothing wrong",
                  file=sys.stderr)
        elif never:
            print(f"hubsgo: warning: {cfg.task}: no state the agent can reach achieves {', '.join(never)}; "
                  "check the layout (a key behind its own door, a walled-in cell, a cell on lava)", file=sys.stderr)
    note_unlinked_goals(resolved)
    plan = None
    if cfg.init_from is not None:       # every refusal before anything is written
        from .transfer import TransferError, plan_transfer

        try:
            plan = plan_transfer(resolved, cfg.init_from, cfg.transfer)
        except TransferError as exc:
            raise RunError(str(exc)) from None
        from ..agents.config import set_keys
        from .transfer import continued_schedules, transfer_defaults

        user_set = set_keys(cfg.overrides, "loop")
        schedules = {} if cfg.restart_schedules else continued_schedules(plan, keep=user_set)
        defaults = transfer_defaults(plan, keep=user_set)
        resolved["hyper"].setdefault("loop", {}).update({**schedules, **defaults})
    created = not out.exists()
    _check_writable(out)
    removed = _tidy(out, RUN_FILES)
    if removed:
        print(f"hubsgo: {out} has no checkpoint (its run stopped before the first one); removed its partial "
              f"files ({', '.join(removed)}) and started the run afresh", file=sys.stderr)
    if resolved.get("subgoals"):
        left = [n for n in get_task(resolved["task_ref"]).catalogue.names if n not in resolved["subgoals"]]
        print(f"hubsgo: model spec {resolved['model']!r} lists {len(resolved['subgoals'])} of the sub-goals of task "
              f"{resolved['task']!r}; not candidates in this run: {', '.join(left)}", file=sys.stderr)
        warn_goals_left_out(resolved["model"], resolved["task_ref"], resolved["subgoals"])
    try:
        env, agent = _build(resolved)
    except BaseException as exc:
        if created:
            with contextlib.suppress(OSError):
                out.rmdir()             # only if still empty
        if not cfg.overrides or not isinstance(exc, (TypeError, ValueError)):
            raise
        msg = " ".join(str(exc).split())
        raise RunError(f"the run cannot be built with --set {' --set '.join(cfg.overrides)}: {msg}") from None
    try:
        if plan is not None:
            from .transfer import TransferError, apply_transfer

            try:
                resolved["init_from"] = {**apply_transfer(agent, plan), "schedules": schedules,
                                         "defaults": defaults}
            except TransferError as exc:
                raise RunError(str(exc)) from None
        write_yaml(out / "config.yaml", resolved)
    except BaseException:
        env.close()
        raise
    return resolved, env, agent, 0.0, None


def train(cfg: RunConfig, out: str | Path, resume: bool = False, progress: bool = True,
          max_episodes: int | None = None, on_episode: Callable[[Any], None] | None = None,
          stop_at: int | None = None) -> dict[str, Any]:
    """Train (or resume) a run into ``out``. ``max_episodes`` stops early (used to test interruption).
    ``stop_at``: pause after the episode that reaches this env step (a checkpoint is written; the
    schedules still run over the whole budget), e.g. to review the critic and revise its spec
    (``hubsgo revise``) before continuing; ``--resume`` continues a paused run as it was.
    Whatever happens, the env, the progress bar and the log files are closed on return."""
    out = Path(out)
    if stop_at is not None and int(stop_at) <= 0:
        raise RunError(f"--stop-at must be a positive env step, got {stop_at}")
    torch.set_num_threads(int(cfg.threads))     # before anything is built, as in a sweep worker
    resolved, env, agent, wall0, purge = _start(cfg, out, resume)
    with contextlib.ExitStack() as closing:
        closing.callback(env.close)
        torch.set_num_threads(int(resolved.get("threads", 1)))
        total = int(resolved["hyper"]["steps"])
        names = list(env.unwrapped.subgoal_names)
        logger = Logger([CSVOutput(out / "metrics.csv")])
        closing.callback(logger.close)
        logger.outputs.append(TensorBoardOutput(out / "tb", purge_step=purge))
        history = CSVOutput(out / "critic_history.csv")
        has_critic = isinstance(agent, HRLLoop) and isinstance(agent.filter, CriticFilter)

        bar = None
        if progress:
            from tqdm.auto import tqdm

            bar = tqdm(total=total, initial=min(agent.env_steps, total), unit="step", dynamic_ncols=True,
                       desc=f"{resolved['agent']}/{resolved['task']}/s{resolved['seed']}")
            closing.callback(bar.close)
        recent: list[tuple[float, float]] = []
        every = int(resolved.get("checkpoint_steps", CHECKPOINT_STEPS))
        last_ckpt = agent.env_steps // every
        t0 = time.perf_counter()
        episodes_this_call = 0
        try:
            while (agent.env_steps < total and (max_episodes is None or episodes_this_call < max_episodes)
                   and (stop_at is None or agent.env_steps < int(stop_at))):
                before = agent.env_steps
                for stats in agent.train_chunk():
                    episodes_this_call += 1
                    wall = wall0 + time.perf_counter() - t0
                    _log_episode(logger, stats, wall)
                    recent = (recent + [(stats.ret, float(stats.success))])[-20:]
                    if has_critic and stats.episode % int(resolved["history_every"]) == 0:
                        marg = agent.filter.marginals()
                        history.write({"episode": stats.episode, "env_steps": stats.env_steps,
                                       **{n: round(float(m), 5) for n, m in zip(names, marg)}}, stats.env_steps)
                    if on_episode is not None:
                        on_episode(stats)
                if agent.env_steps // every > last_ckpt:   # this chunk crossed a multiple of `every`
                    last_ckpt = agent.env_steps // every
                    _save(out, resolved, agent, wall0 + time.perf_counter() - t0)
                if bar is not None and recent:
                    bar.update(min(agent.env_steps, total) - min(before, total))
                    post = {"ret": f"{np.mean([r for r, _ in recent]):.2f}",
                            "succ": f"{np.mean([s for _, s in recent]):.2f}",
                            "eps": f"{stats.filter_eps:.2f}"}
                    if "critic/loss" in stats.scalars:
                        post["critic"] = f"{stats.scalars['critic/loss']:.3g}"
                    bar.set_postfix(post, refresh=False)
        except FloatingPointError as exc:
            kept = (f"{out / CHECKPOINT} holds the last checkpoint" if (out / CHECKPOINT).exists()
                    else "it diverged before its first checkpoint")
            raise FloatingPointError(f"{exc} (env step {agent.env_steps:,}): training diverged; {kept}; start a new "
                                     "run (another --out) with lower learning rates, e.g. --set high.lr=3e-4 "
                                     "--set low.lr=1e-4") from None
        except KeyboardInterrupt:
            raise RunError(f"interrupted; {out / CHECKPOINT} holds the last checkpoint; "
                           f"continue with `hubsgo train {resolved['task_ref']} --out {out} --resume`") from None
        wall = wall0 + time.perf_counter() - t0
        _save(out, resolved, agent, wall)
        plot_run_curve(out, resolved)
        summary: dict[str, Any] = {"run_dir": str(out), "episodes": agent.episodes, "env_steps": agent.env_steps,
                                   "wall_time": round(wall, 2), "finished": agent.env_steps >= total}
        if resolved.get("init_from"):
            summary["init_from"] = resolved["init_from"]
        if has_critic and agent.settled_step is not None and agent.filter.critic.likelihood.settled_scale() != 1.0:
            summary["settled"] = {"step": agent.settled_step, "rate": agent.cfg.settle_at,
                                  "window": agent.cfg.outcome_window}
        if has_critic and agent.env_steps >= total:
            write_json(out / "subgoals.json", subgoal_table(agent.g_star_critic(), names))
    return summary


def read_revisions(run_dir: str | Path) -> list[dict[str, str]]:
    """The rows of ``RUN/revisions.csv`` (none for a run never revised)."""
    return read_csv_rows(Path(run_dir) / REVISIONS_CSV)


def plot_run_curve(run_dir: str | Path, resolved: dict[str, Any] | None = None,
                   path: str | Path | None = None) -> Path | None:
    """``learning_curve.png`` of a run (default ``RUN/learning_curve.png``) from its metrics.csv, with a
    dotted vertical line at the env step of each revision of its critic spec; None without episodes."""
    run_dir = Path(run_dir)
    rows = read_csv_rows(run_dir / "metrics.csv", required=("env_steps", "return", "success"))
    if not rows:
        return None
    if resolved is None:
        resolved = run_config(run_dir)
    path = Path(path) if path is not None else run_dir / "learning_curve.png"
    title = f"{resolved['agent']} on {resolved['task']} (seed {resolved['seed']})"
    steps, rets, succ = ([float(r[k]) for r in rows] for k in ("env_steps", "return", "success"))
    revisions = [(int(r["revision"]), float(r["env_steps"])) for r in read_revisions(run_dir)]
    return plot_learning_curve(steps, rets, succ, path, title=title, revisions=revisions)


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
        if resolved["family"] == "minigrid":
            from ..envs.minigrid.bfs import optimal_return
        for i in range(episodes):
            if resolved["family"] == "minigrid":      # BFS from this episode's start state
                env.reset(seed=episode_seed(base, i))
                optimal.append(float(optimal_return(env)))
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
    write_json(run_dir / "eval.json", result)
    return result
