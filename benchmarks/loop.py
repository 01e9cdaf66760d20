"""Env steps/s of the full HUBS-GO loop next to h-DQN and the raw env (issue 3 benchmark).

Measured side by side in one process with the same seed and budget, on one torch thread:

    .venv/bin/python benchmarks/loop.py --task keydoor --steps 20000

Reports steps/s for: the raw env under random actions; hdqn (the loop with no critic); hubsgo (the
loop with the critic at the preset's ``loop.critic_every``: K high-level minibatches pooled into one
critic update); with ``--strict`` also hubsgo with ``critic_every=1`` (one critic update per
high-level iteration, Algorithm 1 to the letter). The critic's overhead ratio is hdqn steps/s divided
by hubsgo steps/s (target <= 1.15). Use the task's full budget (``--steps 40000`` for KeyDoor) for the
whole-run ratio: late in training options are short and critic updates come more often per env step.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import torch


def raw_env_rate(task: str, steps: int, seed: int) -> float:
    from hubsgo_ppl.envs import make, register

    register()
    env = make(task)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, term, trunc, _ = env.step(int(rng.integers(env.action_space.n)))
        if term or trunc:
            env.reset()
    return steps / (time.perf_counter() - t0)


def agent_rate(task: str, agent: str, steps: int, seed: int, overrides: list[str]) -> tuple[float, dict]:
    from hubsgo_ppl.experiments.run import RunConfig, train

    with tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        summary = train(RunConfig(task=task, agent=agent, steps=steps, seed=seed, overrides=overrides),
                        f"{out}/run", progress=False)
        wall = time.perf_counter() - t0
    return summary["env_steps"] / wall, summary


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="keydoor")
    p.add_argument("--steps", type=int, default=20_000)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--set", action="append", default=[], help="hyperparameter override, as for hubsgo train")
    p.add_argument("--strict", action="store_true", help="also run hubsgo with loop.critic_every=1")
    args = p.parse_args()
    torch.set_num_threads(1)
    raw = raw_env_rate(args.task, args.steps, args.seed)
    hdqn, _ = agent_rate(args.task, "hdqn", args.steps, args.seed, args.set)
    hubsgo, _ = agent_rate(args.task, "hubsgo", args.steps, args.seed, args.set)
    strict = (agent_rate(args.task, "hubsgo", args.steps, args.seed, args.set + ["loop.critic_every=1"])[0]
              if args.strict else None)
    print(f"task {args.task}, {args.steps} env steps, seed {args.seed}, torch threads 1")
    print(f"{'what':<28}{'steps/s':>10}")
    print(f"{'raw env (random actions)':<28}{raw:>10.0f}")
    print(f"{'hdqn loop':<28}{hdqn:>10.0f}")
    print(f"{'hubsgo loop (critic)':<28}{hubsgo:>10.0f}")
    if strict is not None:
        print(f"{'hubsgo, critic_every=1':<28}{strict:>10.0f}   ratio hdqn/hubsgo {hdqn / strict:.2f}")
    print(f"critic overhead ratio hdqn/hubsgo = {hdqn / hubsgo:.2f} (target <= 1.15); "
          f"loop cost vs raw env: hdqn {raw / hdqn:.1f}x, hubsgo {raw / hubsgo:.1f}x")


if __name__ == "__main__":
    main()
