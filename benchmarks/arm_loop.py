"""Where a training run's time goes on an arm task: robosuite's own steps against the HRL loop around them.

    .venv/bin/python benchmarks/arm_loop.py --task push_any_one --steps 3000
    .venv/bin/python benchmarks/arm_loop.py --task push_any_one --steps 3000 --low-level learned \\
        --variant low.train_every=2 --variant low.batch_size=64

Each run is ``hubsgo train``'s (same resolved settings, same seed, one torch thread) minus the files.
Inside it the script times, on the same trajectory, every ``env.step`` (robosuite plus the Gymnasium
wrapper: the raw env steps), the low level's ``act`` and ``observe`` (the learned low level's gradient
steps happen in ``observe``), the high level's updates and the critic's. The loop's overhead is
``(wall - env time) / env time``: what the same episodes cost beyond their env steps (target <= 10%
with the scripted low level). Timing the parts of one run, rather than two runs side by side, keeps
the machine's load out of the ratio. ``--variant KEY=VALUE`` adds a run with that override (each
variant its own run, same seed), for the learned low level's update settings.
"""

from __future__ import annotations

import argparse
import functools
import time
from typing import Any, Callable

import torch

from hubsgo_ppl.experiments.resolve import resolve_run
from hubsgo_ppl.experiments.resolved import RunConfig
from hubsgo_ppl.experiments.restore import build_run


def _timed(obj: Any, name: str, clock: dict[str, float], key: str) -> None:
    """Replace ``obj.name`` by a wrapper that adds its wall time to ``clock[key]``."""
    inner: Callable = getattr(obj, name)

    @functools.wraps(inner)
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return inner(*args, **kwargs)
        finally:
            clock[key] = clock.get(key, 0.0) + time.perf_counter() - start

    setattr(obj, name, wrapper)


def measure(task: str, steps: int, seed: int, low_level: str, overrides: list[str]) -> dict[str, Any]:
    """Train ``steps`` env steps (whole episodes) and return the wall time and its parts (seconds)."""
    torch.set_num_threads(1)
    run = resolve_run(RunConfig(task=task, seed=seed, low_level=low_level, steps=steps, overrides=overrides))
    env, agent = build_run(run)
    clock: dict[str, float] = {}
    for obj, name, key in ((env, "step", "env"), (agent.low, "act", "low_act"), (agent.low, "observe", "low_observe"),
                           (agent.high, "update", "high_update"), (agent.filter, "update", "critic_update")):
        _timed(obj, name, clock, key)
    start = time.perf_counter()
    episodes = successes = 0
    while agent.env_steps < steps:
        for stats in agent.train_chunk():
            episodes += 1
            successes += int(stats.success)
    wall = time.perf_counter() - start
    env.close()
    out = {k: clock.get(k, 0.0) for k in ("env", "low_act", "low_observe", "high_update", "critic_update")}
    out.update(wall=wall, steps=agent.env_steps, episodes=episodes, successes=successes,
               low_updates=int(getattr(agent.low, "updates", 0)))
    return out


def main(argv: list[str] | None = None) -> list[dict[str, Any]]:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--task", default="push_any_one")
    p.add_argument("--steps", type=int, default=3000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--low-level", default="scripted", choices=["scripted", "learned"])
    p.add_argument("--variant", action="append", default=[], help="KEY=VALUE: one more run with this override")
    args = p.parse_args(argv)
    rows = []
    print("| low level | setting | steps | wall s | env s | steps/s | loop overhead | low act s | "
          "low observe (updates) s | low updates | high update s | critic update s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for variant in [None, *args.variant]:
        r = measure(args.task, args.steps, args.seed, args.low_level, [variant] if variant else [])
        r["setting"] = variant or "default"
        rows.append(r)
        print(f"| {args.low_level} | {r['setting']} | {r['steps']} | {r['wall']:.1f} | {r['env']:.1f} | "
              f"{r['steps'] / r['wall']:.1f} | {(r['wall'] - r['env']) / r['env']:.1%} | {r['low_act']:.1f} | "
              f"{r['low_observe']:.1f} | {r['low_updates']} | {r['high_update']:.1f} | "
              f"{r['critic_update']:.1f} |", flush=True)
    return rows


if __name__ == "__main__":
    main()
