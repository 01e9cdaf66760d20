"""One run: seeds, run directory, metrics, checkpoints, resume, evaluation.

Run directory::

    config.yaml            resolved config (task, agent, model spec, hyperparameters, seed, versions)
    metrics.csv            one row per training episode
    critic_history.csv     P(w_i = 1) over training (HUBS-GO)
    tb/                    TensorBoard events
    checkpoint.pt          latest checkpoint, written atomically every ``checkpoint_every`` episodes
    subgoals.json          G*: the configuration ranking from 10,000 critic samples (HUBS-GO)
    learning_curve.png     return and success over environment steps
    eval.json              written by ``evaluate``
"""

from __future__ import annotations

import math
import os
import platform
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from .. import __version__
from ..agents.factory import HIERARCHICAL, build_agent
from ..agents.loop import episode_seed
from ..agents.presets import apply_overrides, preset
from ..envs import get_task, make, register
from ..specs import SpecError
from .io import CheckpointError, load_checkpoint, save_torch, write_json, write_text, write_yaml
from .logger import CSVOutput, Logger, TensorBoardOutput, read_csv_rows
from .plots import plot_learning_curve

__all__ = ["RunConfig", "RunError", "train", "evaluate", "load_run", "subgoal_table", "CHECKPOINT"]

CHECKPOINT = "checkpoint.pt"
FORMAT = 1


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
    checkpoint_every: int = 25        # episodes
    history_every: int = 5            # episodes between critic marginal snapshots
    threads: int = 1                  # torch threads (small nets: 1 is fastest and reproducible)
    overrides: list[str] = field(default_factory=list)


def _critic_from_config(resolved: dict[str, Any]) -> Any:
    from ..infer.critic import SubgoalCritic
    from ..specs import ModelSpec

    spec = ModelSpec.model_validate(resolved["model_spec"])
    return SubgoalCritic.from_spec(spec, seed=int(np.random.SeedSequence([resolved["seed"], 4]).generate_state(1)[0]))


def resolve(cfg: RunConfig) -> dict[str, Any]:
    """Everything a run needs, as plain data (written to config.yaml and into checkpoints)."""
    info = get_task(cfg.task)
    hyper = preset(info.family, info.name)
    if cfg.steps is not None:
        if cfg.steps <= 0:
            raise RunError(f"--steps must be positive, got {cfg.steps}")
        hyper["steps"] = int(cfg.steps)
    if cfg.low_level is not None:
        hyper["low_level"] = cfg.low_level
    try:
        hyper = apply_overrides(hyper, cfg.overrides)
    except ValueError as exc:
        raise RunError(str(exc)) from None
    resolved: dict[str, Any] = {
        "task": info.name, "task_ref": str(cfg.task), "family": info.family,
        "agent": cfg.agent, "seed": int(cfg.seed), "hyper": hyper,
        "checkpoint_every": cfg.checkpoint_every, "history_every": cfg.history_every, "threads": cfg.threads,
        "versions": {"hubsgo_ppl": __version__, "torch": str(torch.__version__), "python": platform.python_version()},
    }
    names = info.catalogue.names
    if cfg.agent == "hubsgo" or cfg.model is not None:
        from ..specs import load_model_spec

        spec = load_model_spec(cfg.model or f"{info.name}-specific", graph=cfg.graph)
        if list(spec.subgoals) != names:
            raise SpecError(
                f"model spec {cfg.model or info.name + '-specific'!r} lists sub-goals {list(spec.subgoals)} "
                f"but task {info.name!r} has {names}; use a spec written for this task "
                f"(e.g. {info.name}-specific) or make its `subgoals` match the catalogue")
        resolved["model_spec"] = spec.model_dump(mode="json")
        resolved["model"] = spec.name
    return resolved


def _build(resolved: dict[str, Any]):
    register()
    env = make(resolved["task_ref"], **resolved["hyper"].get("env", {}))   # built-in name or catalogue path
    critic = _critic_from_config(resolved) if resolved["agent"] == "hubsgo" else None
    agent = build_agent(resolved["agent"], env, resolved["hyper"], resolved["seed"], critic=critic)
    return env, agent


def _check_writable(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write-test"
        probe.write_text("ok")
        probe.unlink()
    except OSError as exc:
        raise RunError(f"--out {out}: cannot write there ({exc.strerror}); choose a writable folder") from None


def _truncate_metrics(path: Path, episodes: int) -> None:
    """Drop rows logged after the checkpoint (episode >= episodes), atomically; keeps everything else."""
    rows = read_csv_rows(path)
    keep = [r for r in rows if int(float(r["episode"])) < episodes]
    if len(keep) == len(rows):
        return
    import csv
    import io

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(rows[0].keys()))
    w.writeheader()
    w.writerows(keep)
    write_text(path, buf.getvalue())


def _log_episode(logger: Logger, stats: Any, wall: float) -> None:
    row = stats.row()
    row["wall_time"] = round(wall, 3)
    for k, v in row.items():
        logger.record(k, v)
    logger.dump(stats.env_steps)
    bad = [k for k, v in stats.scalars.items() if not math.isfinite(float(v))]
    if bad:
        raise FloatingPointError(f"non-finite training statistics {bad} at episode {stats.episode}; "
                                 "lower the learning rates (e.g. --set high.lr=3e-4) and --resume")


def _save(out: Path, resolved: dict[str, Any], agent: Any, wall: float) -> None:
    save_torch(out / CHECKPOINT, {"format": FORMAT, "config": resolved, "agent": agent.state_dict(),
                                   "episodes": agent.episodes, "env_steps": agent.env_steps, "wall_time": wall})


def load_run(run_dir: str | Path):
    """(resolved config, env, agent, checkpoint) of a run directory, agent restored from its checkpoint."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: no such run directory; pass the --out folder of `hubsgo train`")
    ckpt = load_checkpoint(run_dir / CHECKPOINT)
    resolved = ckpt["config"]
    env, agent = _build(resolved)
    try:
        agent.load_state_dict(ckpt["agent"])
    except (KeyError, RuntimeError, ValueError) as exc:
        raise CheckpointError(f"{run_dir / CHECKPOINT}: does not match its own config ({exc}); "
                              "the checkpoint is damaged; start a new run") from None
    return resolved, env, agent, ckpt


def subgoal_table(critic: Any, names: list[str], num_samples: int = 10_000, top_k: int = 5) -> dict[str, Any]:
    ranking = critic.ranking(num_samples=num_samples, top_k=top_k)
    marg = critic.marginals().detach().cpu().numpy().tolist()
    return {"names": names, "num_samples": num_samples, "ranking": ranking,
            "marginals": dict(zip(names, marg)),
            "factors": {"unary": critic.factors()["unary"],
                        "pairwise": {f"{u}--{v}": j for (u, v), j in critic.factors()["pairwise"].items()}}}


def train(cfg: RunConfig, out: str | Path, resume: bool = False, progress: bool = True,
          max_episodes: int | None = None, on_episode: Callable[[Any], None] | None = None) -> dict[str, Any]:
    """Train (or resume) a run into ``out``. ``max_episodes`` stops early (used to test interruption)."""
    out = Path(out)
    ckpt_path = out / CHECKPOINT
    if resume:
        ckpt = load_checkpoint(ckpt_path)
        resolved = ckpt["config"]
        if cfg.steps is not None:
            resolved["hyper"]["steps"] = int(cfg.steps)
        _check_writable(out)
        env, agent = _build(resolved)
        agent.load_state_dict(ckpt["agent"])
        if hasattr(agent, "cfg") and hasattr(agent.cfg, "total_steps"):
            agent.cfg.total_steps = int(resolved["hyper"]["steps"])
        _truncate_metrics(out / "metrics.csv", agent.episodes)
        wall0 = float(ckpt.get("wall_time", 0.0))
    else:
        if ckpt_path.exists():
            raise RunError(f"{out} already holds a run; continue it with --resume or choose another --out")
        resolved = resolve(cfg)
        _check_writable(out)
        env, agent = _build(resolved)
        write_yaml(out / "config.yaml", resolved)
        wall0 = 0.0
    torch.set_num_threads(int(resolved.get("threads", 1)))
    total = int(resolved["hyper"]["steps"])
    names = list(env.unwrapped.subgoal_names)
    logger = Logger([CSVOutput(out / "metrics.csv"), TensorBoardOutput(out / "tb")])
    history = CSVOutput(out / "critic_history.csv")
    has_critic = hasattr(agent, "filter") and hasattr(agent.filter, "critic")

    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=total, initial=min(agent.env_steps, total), unit="step", dynamic_ncols=True,
                   desc=f"{resolved['agent']}/{resolved['task']}/s{resolved['seed']}")
    recent: list[tuple[float, float]] = []
    last_ckpt = agent.episodes // int(resolved["checkpoint_every"])
    t0 = time.perf_counter()
    episodes_this_call = 0
    try:
        while agent.env_steps < total and (max_episodes is None or episodes_this_call < max_episodes):
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
            if agent.episodes // int(resolved["checkpoint_every"]) > last_ckpt:   # crossed a multiple
                last_ckpt = agent.episodes // int(resolved["checkpoint_every"])
                _save(out, resolved, agent, wall0 + time.perf_counter() - t0)
            if bar is not None and recent:
                bar.update(min(agent.env_steps, total) - min(before, total))
                post = {"ret": f"{np.mean([r for r, _ in recent]):.2f}",
                        "succ": f"{np.mean([s for _, s in recent]):.2f}",
                        "eps": f"{stats.filter_eps:.2f}"}
                if "critic/loss" in stats.scalars:
                    post["critic"] = f"{stats.scalars['critic/loss']:.3g}"
                bar.set_postfix(post, refresh=False)
    except KeyboardInterrupt:
        if bar is not None:
            bar.close()
        logger.close()
        raise RunError(f"interrupted; {out / CHECKPOINT} holds the last checkpoint; "
                       f"continue with `hubsgo train {resolved['task']} --out {out} --resume`") from None
    finally:
        if bar is not None:
            bar.close()
    logger.close()
    wall = wall0 + time.perf_counter() - t0
    _save(out, resolved, agent, wall)
    rows = read_csv_rows(out / "metrics.csv")
    if rows:
        plot_learning_curve([float(r["env_steps"]) for r in rows], [float(r["return"]) for r in rows],
                            [float(r["success"]) for r in rows], out / "learning_curve.png",
                            title=f"{resolved['agent']} on {resolved['task']} (seed {resolved['seed']})")
    summary: dict[str, Any] = {"run_dir": str(out), "episodes": agent.episodes, "env_steps": agent.env_steps,
                               "wall_time": round(wall, 2), "finished": agent.env_steps >= total}
    if has_critic and agent.env_steps >= total:
        write_json(out / "subgoals.json", subgoal_table(agent.filter.critic, names))
    env.close()
    return summary


def evaluate(run_dir: str | Path, episodes: int = 10, seed: int | None = None) -> dict[str, Any]:
    """Greedy evaluation (no exploration; HUBS-GO chooses from Ĝt). Writes eval.json."""
    if episodes <= 0:
        raise RunError(f"--episodes must be positive, got {episodes}")
    run_dir = Path(run_dir)
    resolved, env, agent, _ = load_run(run_dir)
    base = int(resolved["seed"]) + 1_000_003 if seed is None else int(seed)
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
    if optimal:
        opt = float(np.mean(optimal))
        result["optimal_return"] = opt
        result["fraction_of_optimal"] = result["mean_return"] / opt if opt > 0 else float("nan")
    write_json(run_dir / "eval.json", result)
    env.close()
    return result
