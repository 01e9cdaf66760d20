"""Building a run's env and agent, restoring them from a checkpoint (``load_run``), and checking that a
``--resume``'s flags leave the recorded run as it is."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

from ..agents.config import resolve_hyper
from ..agents.factory import build_agent
from ..agents.seeding import CRITIC_STREAM, stream_seed
from ..envs import get_task, register
from ..envs.subset import make_subset
from .checkpoint import CHECKPOINT, recorded_run, run_config, run_dir_checkpoint
from .io import CheckpointError
from .resolve import check_catalogue, resolve_run, task_ref
from .resolved import ResolvedRun, RunConfig, RunError, as_resolved

__all__ = ["build_run", "restore", "load_run", "check_resume"]


def _critic(run: ResolvedRun) -> Any:
    from ..infer.critic import SubgoalCritic
    from ..specs import ModelSpec, validate_spec

    # a spec naming a prior or likelihood of the user's own imports it again here: one line if it cannot
    spec = validate_spec(ModelSpec, dict(run.model_spec), source=f"the run's critic spec {run.model!r}")
    return SubgoalCritic.from_spec(spec, seed=stream_seed(run.seed, CRITIC_STREAM))


def build_run(run: ResolvedRun | Mapping[str, Any]):
    """(env, agent) of a resolved run, freshly initialised."""
    run = as_resolved(run)
    register()
    # built-in name or catalogue path; with a ``subgoals`` subset, the task with only those sub-goals
    env = make_subset(run.task_ref, list(run.subgoals) if run.subgoals else None, **run.section("env"))
    try:
        critic = _critic(run) if run.has_critic else None
        agent = build_agent(run.agent, env, run.to_dict()["hyper"], run.seed, critic=critic)
    except BaseException:
        env.close()
        raise
    return env, agent


def restore(path: Path, ckpt: dict[str, Any], steps: int | None = None):
    """(resolved run, env, agent) built from a checkpoint's config with the agent's state loaded;
    ``steps``: a new budget."""
    run = ResolvedRun.from_dict(ckpt["config"], str(path))
    if steps is not None:
        run = run.with_steps(steps)
    changed = check_catalogue(run)
    env, agent = build_run(run)
    try:
        agent.load_state_dict(ckpt["agent"])
    except (KeyError, RuntimeError, ValueError, TypeError, AttributeError) as exc:
        env.close()
        if changed:
            raise CheckpointError(f"{path}: the run's networks do not fit {run.task_ref} as it is now, which "
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
    return run, env, agent


def load_run(run_dir: str | Path):
    """(resolved config as plain data, env, agent, checkpoint) of a run directory, the agent restored
    from its checkpoint."""
    run_dir = Path(run_dir)
    ckpt = run_dir_checkpoint(run_dir)
    run, env, agent = restore(run_dir / CHECKPOINT, ckpt)
    return run.to_dict(), env, agent, ckpt


def _at(tree: Any, path: list[str]) -> Any:
    for key in path:
        if not isinstance(tree, Mapping) or key not in tree:
            return None
        tree = tree[key]
    return tree


def check_resume(out: str | Path, task: str, *, agent: str | None = None, seed: int | None = None,
                 model: str | None = None, graph: str | None = None, low_level: str | None = None,
                 overrides: Sequence[str] = (), init_from: str | None = None) -> None:
    """Refuse (one line) a ``--resume`` whose other flags would change the run in ``out``: a resumed run
    continues as its checkpoint's config (or, before the first checkpoint, its config.yaml) says. Flags
    equal to the run's own pass, so the command that started a run can be repeated with ``--resume``; a
    flag left out (None) is not compared."""
    out = Path(out)
    if (out / CHECKPOINT).exists():
        run = ResolvedRun.from_dict(run_config(out), str(out / "config.yaml"))
    else:
        run = recorded_run(out)
        if run is None:
            return              # nothing recorded to compare with: train says what it can do

    clash = []
    other_task = task not in (run.task, run.task_ref) and task_ref(task) != run.task_ref
    if other_task:      # then a spec is not compared: it would be read against the run's task, not the one given
        clash.append(f"task {task} (the run's is {run.task_ref})")
    if agent is not None and agent != run.agent:
        clash.append(f"--agent {agent} (the run's is {run.agent})")
    if seed is not None and int(seed) != run.seed:
        clash.append(f"--seed {seed} (the run's is {run.seed})")
    if low_level is not None and low_level != run.low_level:
        clash.append(f"--low-level {low_level} (the run's is {run.low_level})")
    ours = dict(run.model_spec or {})
    if model is not None and not other_task:
        theirs = resolve_run(RunConfig(task=run.task_ref, agent="hubsgo", model=model, graph=graph,
                                     steps=run.steps)).model_spec
        if dict(theirs or {}) != ours:
            clash.append(f"--model {model} (the run's spec is {run.model!r}; revise it with `hubsgo revise`)")
    elif graph is not None and not other_task and graph != ours.get("graph"):
        clash.append(f"--graph {graph} (the run's is {ours.get('graph')}; revise the spec with `hubsgo revise`)")
    if overrides:
        info = get_task(run.task_ref)
        try:
            hyper = resolve_hyper(info.family, info.name if info.shipped else None, run.agent, list(overrides),
                                  steps=run.steps, low_level=run.low_level)
        except ValueError as exc:
            raise RunError(str(exc)) from None
        for item in overrides:
            path = item.split("=", 1)[0].strip().split(".")
            if _at(hyper, path) != _at(run.hyper, path):
                clash.append(f"--set {item} (the run's is {_at(run.hyper, path)!r})")
    if init_from is not None:
        source = (run.init_from or {}).get("run")
        if source is None or Path(source).resolve() != Path(init_from).resolve():
            clash.append(f"--init-from {init_from} (the run {'started from ' + source if source else 'started afresh'})")
    if clash:
        raise RunError(f"{out}: --resume continues the run as it was recorded, and "
                       f"{'; '.join(clash)} would change it; drop those flags, or choose another --out for a new run")
