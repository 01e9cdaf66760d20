"""A run's checkpoint and config: building a run's env and agent, saving and loading checkpoints,
reading a run folder back (``run_config``, ``load_run``), and checking a ``--resume``'s flags.

A checkpoint is ``{"format", "config", "agent", "episodes", "env_steps", "wall_time"}``: the agent's
state_dicts and the resolved run as plain data. Its config is checked field by field on every load
(:meth:`ResolvedRun.from_dict`), so a damaged one is refused in one line by every command.
"""

from __future__ import annotations

import errno
import numbers
from pathlib import Path
from typing import Any, Mapping, Sequence

from ..agents.config import resolve_hyper
from ..agents.factory import build_agent
from ..agents.seeding import CRITIC_STREAM, stream_seed
from ..envs import get_task, register
from ..envs.subset import make_subset
from .io import CheckpointError, load_checkpoint, save_torch
from .resolve import check_catalogue, resolve_run, task_ref
from .resolved import ResolvedRun, RunConfig, RunError, as_resolved

__all__ = ["CHECKPOINT", "CHECKPOINT_FORMAT", "RUN_FILES", "EPISODE_LOGS", "G_STAR_SAMPLES", "build_run",
           "save_checkpoint", "read_checkpoint", "read_config_file", "run_config", "run_dir_checkpoint",
           "restore", "load_run", "subgoal_table", "check_resume"]

CHECKPOINT = "checkpoint.pt"
#: version of the checkpoint layout (``{"format", "config", "agent", "episodes", "env_steps", "wall_time"}``)
CHECKPOINT_FORMAT = 1
#: critic samples behind G*, the configuration ranking of subgoals.json
G_STAR_SAMPLES = 10_000
#: what ``train`` writes into a run directory besides the checkpoint (``tb`` is a folder)
RUN_FILES = ("config.yaml", "metrics.csv", "critic_history.csv", "tb", "learning_curve.png", "subgoals.json")
#: per-episode logs, cut back to the checkpoint on resume
EPISODE_LOGS = ("metrics.csv", "critic_history.csv")


def _critic(run: ResolvedRun) -> Any:
    from ..infer.critic import SubgoalCritic
    from ..specs import ModelSpec

    spec = ModelSpec.model_validate(dict(run.model_spec))
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


def _disk_error(exc: BaseException) -> bool:
    """Whether ``exc`` is a write that failed for want of room or a writable disk (torch's zip writer
    reports it as a RuntimeError of its own)."""
    if isinstance(exc, OSError):
        return True
    text = str(exc)
    return isinstance(exc, RuntimeError) and ("PytorchStreamWriter" in text or "file write failed" in text
                                              or "inline_container" in text)


def save_checkpoint(out: Path, run: ResolvedRun | Mapping[str, Any], agent: Any, wall: float) -> None:
    """Write ``out/checkpoint.pt`` atomically; a write that fails (a full disk) leaves the previous one
    as it was and is refused in one line."""
    config = as_resolved(run).to_dict()
    try:
        save_torch(out / CHECKPOINT, {"format": CHECKPOINT_FORMAT, "config": config, "agent": agent.state_dict(),
                                      "episodes": agent.episodes, "env_steps": agent.env_steps, "wall_time": wall})
    except (OSError, RuntimeError) as exc:
        if not _disk_error(exc):
            raise
        reason = (exc.strerror or str(exc)) if isinstance(exc, OSError) else "the write failed"
        if isinstance(exc, OSError) and exc.errno == errno.ENOSPC or "write failed" in str(exc):
            reason = "no space left on the device" if not isinstance(exc, OSError) else reason
        kept = ("the previous checkpoint is intact" if (out / CHECKPOINT).exists() else "there is no earlier one")
        raise RunError(f"{out / CHECKPOINT}: cannot write the checkpoint ({reason}); {kept}; free some space and "
                       f"continue with --resume") from None


def read_checkpoint(path: Path) -> dict[str, Any]:
    """A run's checkpoint, its keys and its config checked (one line where either is damaged)."""
    ckpt = load_checkpoint(path)
    missing = [k for k in ("config", "agent", "episodes", "env_steps") if k not in ckpt]
    if missing:
        raise CheckpointError(f"{path}: not a checkpoint of a `hubsgo train` run (missing {missing}); "
                              "point at a run directory written by `hubsgo train`")
    try:
        ResolvedRun.from_dict(ckpt["config"], f"{path} (its config)")
    except RunError as exc:
        raise CheckpointError(str(exc)) from None
    if not all(isinstance(ckpt[k], numbers.Integral) and not isinstance(ckpt[k], bool) and ckpt[k] >= 0
               for k in ("episodes", "env_steps")) or not isinstance(ckpt["agent"], dict):
        raise CheckpointError(f"{path}: damaged: its episodes, env_steps or agent state are not what "
                              "`hubsgo train` writes; start a new run with another --out")
    return ckpt


def read_config_file(out: Path) -> dict[str, Any] | None:
    """``out/config.yaml`` as a mapping, or None where it is missing or damaged."""
    import yaml

    try:
        cfg = yaml.safe_load((Path(out) / "config.yaml").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    return cfg if isinstance(cfg, dict) else None


def recorded_run(out: Path) -> ResolvedRun | None:
    """The run ``out/config.yaml`` records, or None where it is missing or damaged."""
    cfg = read_config_file(out)
    try:
        return None if cfg is None else ResolvedRun.from_dict(cfg)
    except RunError:
        return None


def run_config(run_dir: str | Path) -> dict[str, Any]:
    """A run's resolved config as plain data: its ``config.yaml``, or the checkpoint's copy where that
    file is missing or damaged."""
    run_dir = Path(run_dir)
    run = recorded_run(run_dir)
    if run is not None:
        return run.to_dict()
    return run_dir_checkpoint(run_dir)["config"]


def run_dir_checkpoint(run_dir: Path) -> dict[str, Any]:
    """The checkpoint of a run directory, with one line where ``run_dir`` is not one."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: no such run directory; pass the --out folder of `hubsgo train`")
    if not (run_dir / CHECKPOINT).is_file():
        raise RunError(f"{run_dir}: not a run directory (no {CHECKPOINT}); pass the --out folder of `hubsgo train`, "
                       "after its first checkpoint")
    return read_checkpoint(run_dir / CHECKPOINT)


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


def subgoal_table(critic: Any, names: list[str], num_samples: int = G_STAR_SAMPLES, top_k: int = 5) -> dict[str, Any]:
    """G*: the ranking of sub-goal sets from ``num_samples`` critic samples, the marginals and factors."""
    ranking = critic.ranking(num_samples=num_samples, top_k=top_k)
    marg = critic.marginals().detach().cpu().numpy().tolist()
    return {"names": names, "num_samples": num_samples, "ranking": ranking,
            "marginals": dict(zip(names, marg)),
            "factors": {"unary": critic.factors()["unary"],
                        "pairwise": {f"{u}--{v}": j for (u, v), j in critic.factors()["pairwise"].items()}}}


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
    if task not in (run.task, run.task_ref) and task_ref(task) != run.task_ref:
        clash.append(f"task {task} (the run's is {run.task_ref})")
    if agent is not None and agent != run.agent:
        clash.append(f"--agent {agent} (the run's is {run.agent})")
    if seed is not None and int(seed) != run.seed:
        clash.append(f"--seed {seed} (the run's is {run.seed})")
    if low_level is not None and low_level != run.low_level:
        clash.append(f"--low-level {low_level} (the run's is {run.low_level})")
    ours = dict(run.model_spec or {})
    if model is not None:
        theirs = resolve_run(RunConfig(task=run.task_ref, agent="hubsgo", model=model, graph=graph)).model_spec
        if dict(theirs or {}) != ours:
            clash.append(f"--model {model} (the run's spec is {run.model!r}; revise it with `hubsgo revise`)")
    elif graph is not None and graph != ours.get("graph"):
        clash.append(f"--graph {graph} (the run's is {ours.get('graph')}; revise the spec with `hubsgo revise`)")
    if overrides:
        info = get_task(run.task_ref)
        try:
            hyper = resolve_hyper(info.family, info.name, run.agent, list(overrides), steps=run.steps,
                                  low_level=run.low_level)
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
