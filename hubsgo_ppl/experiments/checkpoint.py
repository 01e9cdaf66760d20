"""A run's files: its checkpoint (saved atomically, read back checked) and its ``config.yaml``.

A checkpoint is ``{"format", "config", "agent", "episodes", "env_steps", "wall_time"}``: the agent's
state_dicts and the resolved run as plain data. Its config is checked field by field on every load
(:meth:`ResolvedRun.from_dict`), so a damaged one is refused in one line by every command.
"""

from __future__ import annotations

import numbers
import sys
from pathlib import Path
from typing import Any, Mapping

from .io import CheckpointError, load_checkpoint, save_torch
from .resolved import ResolvedRun, RunError, as_resolved

__all__ = ["CHECKPOINT", "CHECKPOINT_FORMAT", "RUN_FILES", "EPISODE_LOGS", "G_STAR_SAMPLES", "save_checkpoint",
           "read_checkpoint", "checkpoint_env_steps", "read_config_file", "recorded_run", "run_config",
           "run_dir_checkpoint", "subgoal_table", "g_star_table", "training_successes",
           "check_episode_log"]

CHECKPOINT = "checkpoint.pt"
#: version of the checkpoint layout (``{"format", "config", "agent", "episodes", "env_steps", "wall_time"}``)
CHECKPOINT_FORMAT = 1
#: critic samples behind G*, the configuration ranking of subgoals.json
G_STAR_SAMPLES = 10_000
#: what ``train`` writes into a run directory besides the checkpoint (``tb`` is a folder)
RUN_FILES = ("config.yaml", "metrics.csv", "critic_history.csv", "tb", "learning_curve.png", "subgoals.json")
#: per-episode logs, cut back to the checkpoint on resume
EPISODE_LOGS = ("metrics.csv", "critic_history.csv")


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
        reason = ((exc.strerror or str(exc)) if isinstance(exc, OSError)
                  else "the write failed, most likely for want of space on the disk")
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


def checkpoint_env_steps(out: str | Path) -> int | None:
    """The env steps ``out``'s checkpoint records (read memory-mapped), or None where there is none or it
    cannot be read (``train --resume`` says why)."""
    try:
        return int(load_checkpoint(Path(out) / CHECKPOINT, mmap=True)["env_steps"])
    except (CheckpointError, KeyError, TypeError, ValueError):
        return None


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
        seeds = sorted(p.parent.name for p in run_dir.glob(f"seed*/{CHECKPOINT}"))
        if seeds:   # the --out folder of `hubsgo train --seeds`: one run per seed below it
            raise RunError(f"{run_dir}: holds one run per seed of `hubsgo train --seeds` ({', '.join(seeds)}); "
                           f"pass one of them, e.g. {run_dir / seeds[0]}")
        raise RunError(f"{run_dir}: not a run directory (no {CHECKPOINT}); pass the --out folder of `hubsgo train`, "
                       "after its first checkpoint")
    return read_checkpoint(run_dir / CHECKPOINT)


def subgoal_table(critic: Any, names: list[str], num_samples: int = G_STAR_SAMPLES, top_k: int = 5) -> dict[str, Any]:
    """G*: the ranking of sub-goal sets from ``num_samples`` critic samples, the marginals and factors,
    and the critic's number of updates (0: G* is its prior's; :func:`g_star_table` adds why)."""
    ranking = critic.ranking(num_samples=num_samples, top_k=top_k)
    marg = critic.marginals().detach().cpu().numpy().tolist()
    return {"names": names, "num_samples": num_samples, "ranking": ranking, "updates": int(critic.num_updates),
            "marginals": dict(zip(names, marg)),
            "factors": {"unary": critic.factors()["unary"],
                        "pairwise": {f"{u}--{v}": j for (u, v), j in critic.factors()["pairwise"].items()}}}


def training_successes(run_dir: str | Path) -> int | None:
    """The training episodes of a run that succeeded, counted in its ``metrics.csv``; None where the
    file is missing or cannot be read."""
    from .io import RunFileError
    from .logger import read_csv_rows

    path = Path(run_dir) / "metrics.csv"
    if not path.is_file():
        return None
    try:
        rows = read_csv_rows(path, required=("success",))
        return sum(1 for r in rows if float(r.get("success") or 0) > 0)
    except (RunFileError, ValueError):
        return None


def g_star_table(agent: Any, names: list[str], run_dir: str | Path, num_samples: int = G_STAR_SAMPLES
                 ) -> dict[str, Any]:
    """``subgoals.json``: :func:`subgoal_table` of the critic G* is read from, with what says why a
    critic that never updated did not: ``successes`` (the run's successful training episodes) and
    ``critic_starts`` (``transitions``: the high level's stored transitions at the critic's first
    update, its ``learning_starts`` or ``batch_size`` and then ``loop.critic_every`` minibatches;
    ``stored``: those it holds), ``critic_from`` (the run an ``--init-from`` critic came from) and
    ``spec_edges`` (the edges of the run's spec: none under ``--graph independent`` or ``fully_connected``
    without a spec of one's own)."""
    table = subgoal_table(agent.g_star_critic(), names, num_samples)
    successes = training_successes(run_dir)
    if successes is not None:
        table["successes"] = successes
    run = recorded_run(Path(run_dir))
    init = (run.init_from or {}) if run is not None else {}
    if run is not None and run.model_spec is not None:      # none: a critic without edges of the user's
        table["spec_edges"] = len(run.model_spec.get("edges") or [])
    if "critic" in (init.get("parts") or ()):       # G* of a critic that never updated here is the source run's
        table["critic_from"] = str(init.get("run"))
    high, cfg = getattr(agent, "high", None), getattr(agent, "cfg", None)
    if hasattr(high, "first_update") and hasattr(cfg, "critic_every"):
        first = int(high.first_update) + int(cfg.critic_every) - 1
        table["critic_starts"] = {"transitions": first, "stored": len(high.buffer)}
    return table


def check_episode_log(run_dir: str | Path, episodes: int) -> None:
    """Refuse (one line, the files left as they are) a ``metrics.csv`` that holds fewer of the episodes
    before the checkpoint than the ``episodes`` it recorded: each episode's row is appended before the
    checkpoint that counts it, so such a file was emptied or cut short, and a resume would lose its
    history. A missing file is a run whose log was moved away, and goes on without it."""
    from .io import RunFileError
    from .logger import read_csv_rows

    path = Path(run_dir) / "metrics.csv"
    if episodes <= 0:
        return
    if not path.is_file():
        print(f"hubsgo: note: {path} is missing: the run goes on without the rows of its first {episodes} "
              "episodes (put the file back before resuming to keep them)", file=sys.stderr)
        return
    rows = read_csv_rows(path, required=("episode",))      # a file that is no CSV log: RunFileError

    def before(row: dict[str, Any]) -> bool:
        try:
            return int(float(row.get("episode") or "")) < episodes
        except ValueError:
            return False

    kept = sum(1 for r in rows if before(r))
    if kept < episodes:
        raise RunFileError(f"{path}: damaged: it holds {kept} of the {episodes} episodes the checkpoint recorded "
                           "(emptied or cut short); put the run's own metrics.csv back, or move it out of the run "
                           "directory to go on without its rows")
