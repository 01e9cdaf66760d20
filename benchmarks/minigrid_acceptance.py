"""The MiniGrid acceptance figures (docs/results.md, "Why the loop conditions Ĝt and breaks low-level cycles") from a sweep folder that
holds the runs of sweeps/keydoor_acceptance.yaml and sweeps/minigrid_acceptance.yaml:

    .venv/bin/hubsgo sweep sweeps/keydoor_acceptance.yaml --workers 2 --out runs/sweeps/acceptance
    .venv/bin/hubsgo sweep sweeps/minigrid_acceptance.yaml --workers 2 --out runs/sweeps/acceptance
    .venv/bin/python benchmarks/minigrid_acceptance.py runs/sweeps/acceptance --episodes 10

For each task and variant it prints, over seeds (mean ± s.e.): the greedy evaluation return (and its
fraction of the BFS-optimal return), the mean episodic return over training, the wall time; for HUBS-GO
runs the top G* set of each seed and the final marginals, and for the incorrect variants the corner
sub-goals' marginals P(w=1).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import evaluate


def mean_se(xs: list[float]) -> str:
    a = np.asarray(xs, dtype=float)
    se = a.std(ddof=1) / math.sqrt(a.size) if a.size > 1 else 0.0
    return f"{a.mean():.4f} ± {se:.4f}"


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("sweep_dir")
    p.add_argument("--episodes", type=int, default=10)
    args = p.parse_args()
    root = Path(args.sweep_dir)
    for task_dir in sorted(d for d in root.iterdir() if d.is_dir() and d.name != "report"):
        for var_dir in sorted(d for d in task_dir.iterdir() if d.is_dir()):
            runs = sorted(var_dir.glob("seed*"))
            if not runs:
                continue
            evals, frac, train_ret, wall, gstar, corners = [], [], [], [], [], []
            for run in runs:
                if not (run / "checkpoint.pt").exists():
                    continue
                r = evaluate(run, episodes=args.episodes)
                evals.append(r["mean_return"])
                frac.append(r.get("fraction_of_optimal", float("nan")))
                rows = read_csv_rows(run / "metrics.csv")
                train_ret.append(float(np.mean([float(x["return"]) for x in rows])))
                wall.append(float(rows[-1]["wall_time"]))
                sg = run / "subgoals.json"
                if sg.exists():
                    table = json.loads(sg.read_text())
                    top = table["ranking"][0]
                    gstar.append(f"{run.name}: {{{', '.join(top['subgoals'])}}} p={top['prob']:.2f}")
                    corners.append({k: v for k, v in table["marginals"].items() if k.startswith("corner")})
            if not evals:
                continue
            print(f"## {task_dir.name} / {var_dir.name} ({len(evals)} seeds)")
            print(f"- greedy eval return ({args.episodes} episodes/seed): {mean_se(evals)}; "
                  f"fraction of BFS optimum {mean_se(frac)}")
            print(f"- mean episodic return over training: {mean_se(train_ret)}")
            print(f"- wall time per run: {np.mean(wall):.0f} s (max {np.max(wall):.0f} s)")
            for g in gstar:
                print(f"- G* {g}")
            if any(corners):
                allc = [v for c in corners for v in c.values()]
                print(f"- corner marginals: max {max(allc):.3f}, mean {np.mean(allc):.3f} "
                      f"({', '.join(f'{k}={v:.2f}' for k, v in corners[0].items())} for seed 0)")
            print()


if __name__ == "__main__":
    main()
