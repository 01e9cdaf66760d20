"""Where the high level's options go in the first episodes of a run: how many env steps are spent in
options towards a sub-goal that no option of those episodes reached from the same achieved set,
although one reached it from another (a door chosen before its key is held, a goal chosen behind a
closed door). These are the options learned initiation sets (``loop.initiation_tries``) leave out.
Per sub-goal it also counts the options towards it and those that reached it (``reach_by_subgoal``),
pooled over the seeds at the end: how well the low level's skills work in those episodes.

The run is re-made from its settings, episode by episode, into a temporary folder (the same seed gives
the same episodes as the run itself) and stops after ``--episodes`` episodes; nothing is written
elsewhere. Per seed it prints one JSON line; then mean ± standard error over the seeds.

    .venv/bin/python scripts/option_audit.py keydoor_moved --set env.obs_mode=egocentric --episodes 20 --seeds 0 1 2 3 4
    .venv/bin/python scripts/option_audit.py keydoor_moved --set env.obs_mode=egocentric --episodes 20 \\
        --init-from 'runs/measure_transfer_ego/keydoor-to-keydoor_moved/seed{seed}/source'

``--init-from`` takes ``{seed}`` for the seed's own source run, as ``hubsgo train --init-from``
otherwise (``--transfer`` as there).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def audit(options: list[dict]) -> dict[str, float]:
    """The measures of one run's option log (``EpisodeStats.option_log`` of its episodes, in order)."""
    reached_from: dict[str, set[frozenset[str]]] = {}
    for o in options:
        if o["reached"]:
            reached_from.setdefault(o["goal"], set()).add(frozenset(o["from"]))
    steps = sum(o["steps"] for o in options)
    never = [o for o in options
             if frozenset(o["from"]) not in reached_from.get(o["goal"], set()) and reached_from.get(o["goal"])]
    return {"options": len(options), "steps": steps, "never_options": len(never),
            "never_steps": sum(o["steps"] for o in never),
            "never_step_share": sum(o["steps"] for o in never) / max(steps, 1)}


def reach_by_subgoal(options: list[dict]) -> dict[str, list[int]]:
    """Per sub-goal, ``[options towards it, those that reached it]``, sub-goals in name order."""
    counts: dict[str, list[int]] = {}
    for o in options:
        c = counts.setdefault(o["goal"], [0, 0])
        c[0] += 1
        c[1] += bool(o["reached"])
    return dict(sorted(counts.items()))


def one(task: str, seed: int, episodes: int, overrides: list[str], init_from: str | None,
        transfer: list[str] | None) -> list[dict]:
    """The option log of the first ``episodes`` episodes of the run of ``task`` and ``seed``, re-made."""
    import torch

    from hubsgo_ppl.experiments.run import RunConfig, train

    torch.set_num_threads(1)
    log: list[dict] = []
    cfg = RunConfig(task=task, seed=seed, overrides=overrides,
                    init_from=None if init_from is None else init_from.format(seed=seed), transfer=transfer)
    with tempfile.TemporaryDirectory() as tmp:
        train(cfg, Path(tmp) / "run", progress=False, max_episodes=episodes,
              on_episode=lambda stats: log.extend(stats.option_log))
    return log


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("task")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--init-from", help="a source run; {seed} is replaced by the seed")
    p.add_argument("--transfer", help="with --init-from: critic,high,low (default: all that apply)")
    args = p.parse_args(argv)
    from measure_common import mean_se

    transfer = None if args.transfer is None else args.transfer.split(",")
    logs = [one(args.task, s, args.episodes, args.overrides, args.init_from, transfer) for s in args.seeds]
    rows = [{"seed": s, **audit(log), "by_subgoal": reach_by_subgoal(log)} for s, log in zip(args.seeds, logs)]
    for row in rows:
        print(json.dumps(row))
    for key, fmt in (("steps", ",.0f"), ("never_steps", ",.0f"), ("never_step_share", ".3f")):
        m, se = mean_se(r[key] for r in rows)
        print(f"{key}: {m:{fmt}} ± {se:{fmt}} over {len(rows)} seeds")
    for goal, (tried, reached) in reach_by_subgoal([o for log in logs for o in log]).items():
        print(f"options towards {goal}: {reached} of {tried} reached it ({reached / tried:.3f}), pooled over the seeds")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
