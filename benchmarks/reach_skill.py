"""Reach skill of the learned low level (GoalTD3 + HER) on a robosuite arm task.

Acceptance: with the learned low level, the reach skill reaches at least 0.9 greedy success within a
stated budget (``--budget``; ``--target`` sets the bar). Each episode draws a random target region in
the arm's workspace above the table (a sphere of radius ``tolerance`` around a point; gripper command
+-1 at random) and gives the policy ``--episode-steps`` control steps to bring the end effector into
it with the gripper command applied. Training uses GoalTD3 exactly as the HRL loop does (``act`` /
``observe`` / ``begin_option``); every ``--eval-every`` training steps, greedy success over
``--eval-episodes`` fixed held-out targets is measured, and training stops once it reaches ``--target``.

    .venv/bin/python benchmarks/reach_skill.py --task stack_cubes --budget 6000 --seed 0

The learned arm low level starts from the skill this trains (``GoalTD3Config.skill``), made with

    .venv/bin/python benchmarks/reach_skill.py --budget 6000 --target 1.0 --save hubsgo_ppl/agents/reach_skill.pt

Prints one JSON line per evaluation and a final JSON summary (budget, steps used, success, wall time).
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np
import torch

from hubsgo_ppl.agents.td3_her import GoalTD3
from hubsgo_ppl.envs.robosuite import make_robosuite_task
from hubsgo_ppl.resources import envs_dir


class RandomTargets:
    """Stands in for ``env.unwrapped`` towards GoalTD3: sub-goal 0 is the current random target."""

    def __init__(self, env, rng: np.random.Generator, half_xy: float, z_range: tuple[float, float]):
        self.env, self.rng = env, rng
        self.half_xy, self.z_range = half_xy, z_range
        self.centre = np.zeros(3)
        self.target, self.gripper = np.zeros(3), -1.0

    @property
    def unwrapped(self):
        return self

    def draw(self) -> None:
        task = self.env.unwrapped.task
        c = np.array([task.table_offset[0], task.table_offset[1], task.table_top])
        xy = c[:2] + self.rng.uniform(-self.half_xy, self.half_xy, 2)
        z = c[2] + self.rng.uniform(*self.z_range)
        self.target, self.gripper = np.array([xy[0], xy[1], z]), float(self.rng.choice([-1.0, 1.0]))

    def subgoal_target(self, i: int):
        return self.target, self.gripper


def episode(env, targets: RandomTargets, agent: GoalTD3, seed: int, steps: int, explore: float,
            train: bool) -> bool:
    obs, _ = env.reset(seed=seed)
    targets.draw()
    agent.begin_option()
    a = np.zeros(4, np.float32)
    for _ in range(steps):
        a = agent.act(obs, 0, explore, targets)
        nxt, *_ = env.step(a)
        if train:
            agent.observe(obs, a, nxt, None, None, False)
        obs = nxt
    reached = np.linalg.norm(env.unwrapped.eef_position() - targets.target) < agent.cfg.tolerance
    return bool(reached and abs(a[3] - targets.gripper) < agent.cfg.gripper_tolerance)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--task", default="stack_cubes", help="robosuite task whose arm and table are used")
    p.add_argument("--budget", type=int, default=6000, help="training env steps at most")
    p.add_argument("--episode-steps", type=int, default=40, help="control steps per reach episode (20 Hz)")
    p.add_argument("--eval-every", type=int, default=1000, help="training steps between evaluations")
    p.add_argument("--eval-episodes", type=int, default=20)
    p.add_argument("--target", type=float, default=0.9, help="stop once greedy success reaches this")
    p.add_argument("--half-xy", type=float, default=0.15, help="targets within +-this (m) of the table centre")
    p.add_argument("--explore", type=float, default=0.5, help="explore_eps while training")
    p.add_argument("--set", nargs="*", default=[], help="GoalTD3Config overrides, e.g. use_obs=false")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--save", default=None, help="write the trained networks here (the shipped skill: "
                   "hubsgo_ppl/agents/reach_skill.pt)")
    args = p.parse_args(argv)
    torch.set_num_threads(1)

    import yaml

    low_cfg = {"hidden": [128, 128], "batch_size": 128, "learning_starts": 500, "use_obs": False, "skill": None}
    for item in args.set:
        k, v = item.split("=", 1)
        low_cfg[k] = yaml.safe_load(v)
    env = make_robosuite_task(str(envs_dir() / f"{args.task}.yaml"), horizon=10**6)
    seq = np.random.SeedSequence(args.seed)
    s_torch, s_agent, s_train, s_eval = seq.spawn(4)
    agent = GoalTD3.for_env(env, low_cfg, torch.Generator().manual_seed(int(s_torch.generate_state(1)[0])),
                            np.random.default_rng(s_agent))
    train_targets = RandomTargets(env, np.random.default_rng(s_train), args.half_xy, (0.03, 0.3))
    eval_seeds = [int(s) for s in np.random.SeedSequence([args.seed, 99]).generate_state(args.eval_episodes)]

    t0 = time.perf_counter()
    steps, ep, history = 0, 0, []
    success = 0.0
    while steps < args.budget:
        episode(env, train_targets, agent, seed=ep, steps=args.episode_steps, explore=args.explore, train=True)
        steps += args.episode_steps
        ep += 1
        if steps % args.eval_every < args.episode_steps or steps >= args.budget:
            # the held-out targets are the same at every evaluation (their own generator, re-made)
            eval_targets = RandomTargets(env, np.random.default_rng([args.seed, 7]), args.half_xy, (0.03, 0.3))
            success = float(np.mean([episode(env, eval_targets, agent, s, args.episode_steps, 0.0, False)
                                     for s in eval_seeds]))
            row = {"train_steps": steps, "greedy_success": success, "wall_s": round(time.perf_counter() - t0, 1)}
            history.append(row)
            print(json.dumps(row), flush=True)
            if success >= args.target:
                break
    summary = {"task": args.task, "budget": args.budget, "train_steps": steps, "episodes": ep,
               "episode_steps": args.episode_steps, "eval_episodes": args.eval_episodes,
               "greedy_success": success, "reached_target": success >= args.target,
               "wall_s": round(time.perf_counter() - t0, 1), "low_cfg": low_cfg, "seed": args.seed,
               "python": platform.python_version(), "torch": str(torch.__version__)}
    print(json.dumps(summary))
    if args.save:
        agent.save_skill(args.save, summary)
    env.close()
    return summary


if __name__ == "__main__":
    main()
