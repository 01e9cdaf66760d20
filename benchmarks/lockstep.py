"""Wall time of several seeds trained in lockstep in one process against one seed alone, and of one
seed of an agent against another (e.g. HUBS-GO against SB3's DQN), whole processes side by side:

    .venv/bin/python benchmarks/lockstep.py --task keydoor --steps 10000 --seeds 0 1 2 3 4 --pairs 3
    .venv/bin/python benchmarks/lockstep.py --task keydoor --steps 10000 --seeds 0 1 2 3 4 --workers 2 --pairs 3
    .venv/bin/python benchmarks/lockstep.py --task keydoor --steps 20000 --against dqn --pairs 3

Each measurement is one ``hubsgo train`` process (imports, building the run, training, the end-of-run
files), timed from outside. The two commands of a pair run one after the other, in alternating order
(A then B, B then A, ...), so that a drift in the machine's speed falls on both; the script prints
each pair's ratio and the median of the pairs' ratios. ``--seeds`` (default) compares
``hubsgo train TASK --seeds S0 S1 ... --workers W`` with ``hubsgo train TASK --seed S0``; ``--against AGENT``
compares ``--seed S0`` of ``--agent`` (default hubsgo) with ``--seed S0`` of AGENT, per env step.

``--split`` instead trains one seed in this process and prints where its wall time goes (imports,
building the run, the low level's and the high level's gradient steps, the critic's updates, acting,
the env, logging, the end-of-run files), timed around those calls:

    .venv/bin/python benchmarks/lockstep.py --task keydoor --steps 20000 --split
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def timed(args: list[str]) -> float:
    """Seconds of one ``hubsgo`` process (its output discarded; a failure stops the benchmark)."""
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "hubsgo_ppl.cli", *args], check=True, env=env,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def split(task: str, agent: str, steps: int, seed: int) -> None:
    """One run in this process, its wall time split by the calls that take it."""
    t0 = time.perf_counter()
    import torch  # noqa: F401  (the imports a run pays, timed with the rest below)

    from hubsgo_ppl.agents import filters, high_level, low_level
    from hubsgo_ppl.experiments import callbacks, driver
    from hubsgo_ppl.experiments.run import RunConfig, train

    imports = time.perf_counter() - t0
    spent: dict[str, float] = {}
    parts = {"build or restore the run": (driver.RunSession, "__init__"),
             "low level: gradient steps": (low_level.GoalDQN, "update"),
             "low level: acting": (low_level.GoalDQN, "act"),
             "high level: gradient steps": (high_level.HighLevelDQN, "update"),
             "high level: choosing": (high_level.HighLevelDQN, "select"),
             "critic: updates and Ĝt": (filters.CriticFilter, "update"),
             "logging an episode": (driver.RunSession, "log"),
             "checkpoints": (callbacks.CheckpointCallback, "on_chunk_end"),
             "end of run (final checkpoint, G*, curve)": (callbacks.CallbackList, "on_training_end")}
    for name, (owner, attr) in parts.items():
        orig = getattr(owner, attr)

        def timed(*a, _orig=orig, _name=name, **kw):
            t = time.perf_counter()
            try:
                return _orig(*a, **kw)
            finally:
                spent[_name] = spent.get(_name, 0.0) + time.perf_counter() - t

        setattr(owner, attr, timed)
    with tempfile.TemporaryDirectory() as tmp:
        t1 = time.perf_counter()
        summary = train(RunConfig(task=task, agent=agent, steps=steps, seed=seed), f"{tmp}/run", progress=False)
        total = time.perf_counter() - t1 + imports
    inner = sum(spent.values())         # the timed calls do not nest
    print(f"{task}, {agent}, seed {seed}, {summary['env_steps']} env steps: {total:.1f} s in this process")
    print(f"{'part':<44}{'s':>8}{'share':>8}")
    for name, sec in [("imports", imports), *spent.items(),
                      ("the rest of the loop (env steps, replay, bookkeeping)", total - imports - inner)]:
        print(f"{name:<44}{sec:>8.1f}{sec / total:>8.0%}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", default="keydoor")
    p.add_argument("--agent", default="hubsgo")
    p.add_argument("--steps", type=int, default=10_000)
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    p.add_argument("--against", metavar="AGENT", help="compare one seed with one seed of this agent instead")
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--workers", type=int, default=1, help="processes sharing the lockstep seeds (hubsgo train --workers)")
    p.add_argument("--split", action="store_true", help="where one seed's wall time goes (in this process)")
    args = p.parse_args()
    if args.split:
        split(args.task, args.agent, args.steps, args.seeds[0])
        return
    base = ["train", args.task, "--steps", str(args.steps), "--no-progress"]
    with tempfile.TemporaryDirectory() as tmp:
        def run(which: str, i: int) -> float:
            s0 = str(args.seeds[0])
            if args.against is None:
                cmd = ["--agent", args.agent] + (["--seeds", *map(str, args.seeds), "--workers", str(args.workers)]
                                                 if which == "a" else ["--seed", s0])
            else:
                cmd = ["--agent", args.agent if which == "a" else args.against, "--seed", s0]
            return timed(base + cmd + ["--out", f"{tmp}/{which}{i}"])

        ratios, times = [], {"a": [], "b": []}
        for i in range(args.pairs):
            order = ("a", "b") if i % 2 == 0 else ("b", "a")
            got = {w: run(w, i) for w in order}
            for w in "ab":
                times[w].append(got[w])
            ratios.append(got["a"] / got["b"])
            print(f"pair {i}: A {got['a']:.1f} s, B {got['b']:.1f} s, A/B {ratios[-1]:.2f}", flush=True)
    if args.against is None:
        what = (f"A = {len(args.seeds)} seeds of {args.agent} in lockstep on {args.workers} worker(s), "
                "B = one seed alone")
    else:
        what = f"A = one seed of {args.agent}, B = one seed of {args.against}"
    print(f"{args.task}, {args.steps} env steps, {what}")
    print(f"median A {statistics.median(times['a']):.1f} s, B {statistics.median(times['b']):.1f} s; "
          f"median of the pairs' ratios A/B = {statistics.median(ratios):.2f} "
          f"(spread {min(ratios):.2f}-{max(ratios):.2f})")


if __name__ == "__main__":
    main()
