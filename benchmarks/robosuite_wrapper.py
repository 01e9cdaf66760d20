"""Env steps/s through the Gymnasium wrapper next to raw robosuite, measured side by side.

"Raw" is the very same robosuite task object (same robot, OSC_POSITION controller, same MjSim) stepped
through robosuite's own ``env.step`` (observation dict, reward); "wrapper" is ``RobosuiteTaskEnv.step``
on top of it, which adds the flat float32 observation, ``info["subgoals"]`` (every sub-goal predicate)
and termination. Blocks of each alternate, from the same seeded state with the same seeded actions, so
machine load hits both alike; the overhead is computed from the medians. Target: overhead <= 10%.

    .venv/bin/python benchmarks/robosuite_wrapper.py --steps 150 --rounds 3
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

from hubsgo_ppl.envs.robosuite import make_robosuite_task
from hubsgo_ppl.resources import envs_dir

TASKS = ("stack_cubes", "push_any_one", "collect_three_balls")


def _block(step, actions: np.ndarray) -> float:
    start = time.perf_counter()
    for a in actions:
        step(a)
    return len(actions) / (time.perf_counter() - start)


def measure(task: str, steps: int, rounds: int, seed: int = 0) -> dict:
    env = make_robosuite_task(str(envs_dir() / f"{task}.yaml"), horizon=10**9)
    # small random actions keep the arm in its workspace for the whole block
    actions = np.random.default_rng(seed).uniform(-0.3, 0.3, (steps, 4)).astype(np.float32)
    raw, wrapped = [], []
    _block(env.step, actions[:20])     # warm-up (first-step allocations)
    for _ in range(rounds):
        env.reset(seed=seed)
        raw.append(_block(env.task.step, actions))
        env.reset(seed=seed)
        wrapped.append(_block(env.step, actions))
    # the wrapper's own work per step, timed alone: far below the noise of a loaded machine
    obs = env.task._get_observations()
    start = time.perf_counter()
    for _ in range(1000):
        env._flat(obs)
        env._info(False)
    extra = (time.perf_counter() - start) / 1000
    env.close()
    r, w = float(np.median(raw)), float(np.median(wrapped))
    return {"task": task, "raw_steps_per_s": r, "wrapper_steps_per_s": w, "overhead": 1.0 - w / r,
            "wrapper_work_us": 1e6 * extra, "wrapper_work_share": extra * r, "raw_all": raw, "wrapper_all": wrapped}


def main(argv: list[str] | None = None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tasks", nargs="+", default=list(TASKS), choices=TASKS, help="tasks to measure")
    parser.add_argument("--steps", type=int, default=150, help="env steps per timed block")
    parser.add_argument("--rounds", type=int, default=3, help="alternating raw/wrapper block pairs per task")
    parser.add_argument("--json", help="also write the results to this JSON file")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.rounds < 1:
        parser.error("--steps and --rounds must be >= 1")
    results = [measure(t, args.steps, args.rounds) for t in args.tasks]
    print(f"# {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"{args.rounds} x {args.steps} steps per side")
    print("| task | raw robosuite steps/s | wrapper steps/s | overhead (medians) | wrapper work/step "
          "| share of a raw step |")
    print("|---|---:|---:|---:|---:|---:|")
    for r in results:
        print(f"| {r['task']} | {r['raw_steps_per_s']:.1f} | {r['wrapper_steps_per_s']:.1f} | "
              f"{100 * r['overhead']:.1f}% | {r['wrapper_work_us']:.0f} us | {100 * r['wrapper_work_share']:.1f}% |")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(results, fh, indent=2)
    return results


if __name__ == "__main__":
    main()
