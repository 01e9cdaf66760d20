"""How reliably the scripted arm low level (``hubsgo_ppl.agents.scripted_osc.ScriptedOSC``) carries out
each arm task's correct sub-goal sequence, every sub-goal until it is achieved (at most ``--per-goal``
steps), on fixed reset seeds:

    .venv/bin/python benchmarks/scripted_osc.py                 # seeds 10-19, 300 steps per sub-goal
    .venv/bin/python benchmarks/scripted_osc.py --seeds 10 11 --tasks stack_cubes

Per task it prints the successes, the env steps per episode (median / max) and the end effector's
path length (m, median). PushAnyOne pushes one cube, the colour cycling red, green, blue with the seed.
"""

from __future__ import annotations

import argparse

import numpy as np

SEQUENCES = {
    "stack_cubes": lambda seed: ["grasp_red", "place_red_on_target", "grasp_green", "place_green_on_red"],
    "push_any_one": lambda seed: [f"push_{c}_to_{c}" for c in [("red", "green", "blue")[seed % 3]]],
    "collect_three_balls": lambda seed: ["collect_ball_0", "collect_ball_1", "collect_ball_2"],
}


def run_sequence(env, controller, names: list[str], seed: int, per_goal: int) -> tuple[bool, int, float]:
    """(success, env steps, end-effector path in m) of one episode that runs ``names`` in order."""
    _, info = env.reset(seed=seed)
    steps, path, prev = 0, 0.0, env.unwrapped.eef_position()
    terminated = truncated = False
    for name in names:
        i = env.unwrapped.subgoal_names.index(name)
        for _ in range(per_goal):
            if info["subgoals"][i] or terminated or truncated:
                break
            _, _, terminated, truncated, info = env.step(controller.act(env, i))
            steps += 1
            now = env.unwrapped.eef_position()
            path, prev = path + float(np.linalg.norm(now - prev)), now
    return bool(info.get("is_success", False)), steps, path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tasks", nargs="+", default=list(SEQUENCES), choices=list(SEQUENCES))
    p.add_argument("--seeds", nargs="+", type=int, default=list(range(10, 20)))
    p.add_argument("--per-goal", type=int, default=300)
    args = p.parse_args()

    from hubsgo_ppl.agents.scripted_osc import ScriptedOSC
    from hubsgo_ppl.envs.robosuite import make_robosuite_task
    from hubsgo_ppl.resources import envs_dir

    print("| task | sequence | success | steps (median / max) | path, m (median) |")
    print("|---|---|---:|---:|---:|")
    for task in args.tasks:
        env = make_robosuite_task(str(envs_dir() / f"{task}.yaml"))
        try:
            runs = [run_sequence(env, ScriptedOSC(), SEQUENCES[task](s), s, args.per_goal) for s in args.seeds]
        finally:
            env.close()
        ok = sum(r[0] for r in runs)
        steps = [r[1] for r in runs]
        print(f"| {task} | {', '.join(SEQUENCES[task](args.seeds[0]))} | {ok}/{len(runs)} | "
              f"{np.median(steps):.0f} / {max(steps)} | {np.median([r[2] for r in runs]):.2f} |", flush=True)


if __name__ == "__main__":
    main()
