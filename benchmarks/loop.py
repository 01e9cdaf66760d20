"""Env steps/s of the full HUBS-GO loop next to h-DQN and the raw env (the critic's loop overhead).

Measured side by side in one process with the same seed and budget, on one torch thread:

    .venv/bin/python benchmarks/loop.py --task keydoor --steps 40000 --seeds 0 1

Reports steps/s for: the raw env under random actions; hdqn (the loop with no critic); hubsgo (the
loop with the critic at the preset's ``loop.critic_every``: K high-level minibatches pooled into one
critic update); with ``--strict`` also hubsgo with ``critic_every=1`` (one critic update per
high-level iteration, Algorithm 1 to the letter). The critic's overhead ratio is hdqn steps/s divided
by hubsgo steps/s (target <= 1.15). Use the task's full budget (``--steps 40000`` for KeyDoor) for the
whole-run ratio: late in training options are short and critic updates come more often per env step.

The two agents do not run the same episodes (h-DQN may still be wandering where HUBS-GO already takes
short options), so the side-by-side ratio mixes the critic's cost with behaviour. The script therefore
also times the critic's own updates inside the HUBS-GO run and reports the like-for-like ratio
``wall / (wall - critic time)``: what the same trajectory would cost without the critic. ``--seeds``
sums steps and wall time over several seeds. The runs are interleaved by seed in alternating order
(h-DQN then HUBS-GO for the first seed, HUBS-GO then h-DQN for the second, ...), so that a drift in the
machine's speed during the measurement falls on both agents alike; each seed's own ratio is printed too.
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


class CriticTimer:
    """Times ``CriticFilter.update`` (the critic's Eq. 5 step and the read of Ĝt) while active."""

    def __init__(self):
        self.seconds = 0.0

    def __enter__(self):
        from hubsgo_ppl.agents.filters import CriticFilter

        self._orig = CriticFilter.update
        timer = self

        def timed(filt, batch):
            t0 = time.perf_counter()
            try:
                return timer._orig(filt, batch)
            finally:
                timer.seconds += time.perf_counter() - t0

        CriticFilter.update = timed
        return self

    def __exit__(self, *exc):
        from hubsgo_ppl.agents.filters import CriticFilter

        CriticFilter.update = self._orig


def agent_run(task: str, agent: str, steps: int, seed: int, overrides: list[str]) -> tuple[int, float, float]:
    """(env steps, wall seconds, seconds inside critic updates) of one training run."""
    from hubsgo_ppl.experiments.run import RunConfig, train

    with CriticTimer() as timer, tempfile.TemporaryDirectory() as out:
        t0 = time.perf_counter()
        summary = train(RunConfig(task=task, agent=agent, steps=steps, seed=seed, overrides=overrides),
                        f"{out}/run{seed}", progress=False)
        wall = time.perf_counter() - t0
    return int(summary["env_steps"]), wall, timer.seconds


def interleaved(task: str, steps: int, seeds: list[int], overrides: dict[str, list[str]]) -> dict[str, list]:
    """Per agent, the (env steps, wall, critic seconds) of each seed, the agents alternating in order."""
    agents = list(overrides)
    out: dict[str, list] = {a: [] for a in agents}
    for i, seed in enumerate(seeds):
        for agent in (agents if i % 2 == 0 else agents[::-1]):
            out[agent].append(agent_run(task, agent, steps, seed, overrides[agent]))
    return out


def _sum(runs: list) -> tuple[int, float, float]:
    """Steps, wall and critic seconds summed over runs."""
    return tuple(map(sum, zip(*runs)))


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="keydoor")
    p.add_argument("--steps", type=int, default=20_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0], help="seeds; steps and time are summed")
    p.add_argument("--set", action="append", default=[], help="hyperparameter override, as for hubsgo train")
    p.add_argument("--hubsgo-set", action="append", default=[],
                   help="an override for the HUBS-GO run only (e.g. loop.low_goal_weight=uniform)")
    p.add_argument("--strict", action="store_true", help="also run hubsgo with loop.critic_every=1")
    args = p.parse_args()
    torch.set_num_threads(1)
    raw = raw_env_rate(args.task, args.steps, args.seeds[0])
    runs = interleaved(args.task, args.steps, args.seeds,
                       {"hdqn": args.set, "hubsgo": args.set + args.hubsgo_set})
    (h_steps, h_wall, _), (g_steps, g_wall, g_critic) = _sum(runs["hdqn"]), _sum(runs["hubsgo"])
    hdqn, hubsgo = h_steps / h_wall, g_steps / g_wall
    print(f"task {args.task}, {args.steps} env steps x seeds {args.seeds}, torch threads 1")
    print(f"{'what':<28}{'steps/s':>10}")
    print(f"{'raw env (random actions)':<28}{raw:>10.0f}")
    print(f"{'hdqn loop':<28}{hdqn:>10.0f}")
    print(f"{'hubsgo loop (critic)':<28}{hubsgo:>10.0f}   critic updates {g_critic:.1f} s of {g_wall:.1f} s")
    if args.strict:
        s_steps, s_wall, s_critic = _sum([agent_run(args.task, "hubsgo", args.steps, seed,
                                                    args.set + args.hubsgo_set + ["loop.critic_every=1"])
                                          for seed in args.seeds])
        strict = s_steps / s_wall
        print(f"{'hubsgo, critic_every=1':<28}{strict:>10.0f}   ratio hdqn/hubsgo {hdqn / strict:.2f}, "
              f"like-for-like {s_wall / (s_wall - s_critic):.2f}")
    for seed, h, g in zip(args.seeds, runs["hdqn"], runs["hubsgo"]):
        print(f"{f'  seed {seed}':<28}hdqn/hubsgo {(h[0] / h[1]) / (g[0] / g[1]):.2f} side by side")
    print(f"critic overhead ratio hdqn/hubsgo = {hdqn / hubsgo:.2f} side by side, "
          f"{g_wall / (g_wall - g_critic):.2f} like-for-like (same trajectory without the critic) "
          f"(target <= 1.15); loop cost vs raw env: hdqn {raw / hdqn:.1f}x, hubsgo {raw / hubsgo:.1f}x")

if __name__ == "__main__":
    main()
