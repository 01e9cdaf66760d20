"""Measure what ``hubsgo train NEW_TASK --init-from RUN`` is worth on the similar-task pairs.

A sweep file cannot express this (each target run starts from the source run of its seed), so this
script runs it. For each pair (``keydoor -> keydoor_moved``, ``fourroom -> fourroom_moved``,
``threepair -> threepair_moved``; ``vault -> vault_moved``, ``annex -> annex_wide``,
``gallery -> gallery_turned`` and ``moat -> moat_mirror`` with ``--sources vault annex gallery moat``) and each
seed: a HUBS-GO run on the source task at its budget, then runs on the target task at its budget,
one per arm:

- ``scratch``: no transfer;
- ``critic``, ``high``, ``low``: that part alone (``--transfer critic`` ...);
- ``all``: critic, high level and low level together;
- ``all_restarted``: the same with ``--restart-schedules`` (the exploration schedules start afresh
  instead of where the source run left them);
- ``critic_low``: the critic and the low level, the high level learning afresh.

Per arm it reports, as mean ± standard error over the seeds, the env steps until the rolling success
rate (20 episodes) first reaches 90% (runs that never reach it are counted, not averaged) and the
success rate over the last 20 episodes; a second table pairs the seeds, each transfer arm's steps to
90% success minus the scratch run's of the same seed. Everything goes under ``--out``: the runs, ``results.csv``
(one row per target run) and ``summary.md``. Re-running skips finished runs, so ``--out`` remembers its
settings (``settings.json``: ``--steps``, ``--set``, ``--source-set``, ``--restart-schedules``) and refuses other ones;
more seeds, sources or arms may be added. To reuse source runs under other settings, copy their
folders into a new ``--out``.

    .venv/bin/python scripts/measure_transfer.py --out runs/measure_transfer        # 3 pairs x 5 seeds x 7 arms
    .venv/bin/python scripts/measure_transfer.py --out runs/smoke_transfer --smoke   # a pipeline check

``--smoke``: one seed, keydoor -> keydoor_moved only, 1,000 steps per run and tiny networks; it
checks that the pipeline runs, and measures nothing.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path
from measure_common import (SMOKE, WINDOW, finish, guard_settings, output_dir, paired_lines, parser, run_jobs,  # noqa: E402
                            steps_to, summary_table)  # noqa: E402  (a sibling script module)

ROOT = Path(__file__).resolve().parents[1]
PAIRS = {"keydoor": "keydoor_moved", "fourroom": "fourroom_moved", "threepair": "threepair_moved",
         "annex": "annex_wide", "gallery": "gallery_turned",
         "vault": "vault_moved", "moat": "moat_mirror"}
DEFAULT_SOURCES = ["keydoor", "fourroom", "threepair"]     # the pairs of the transfer tables (docs/results.md)
ARMS = {"scratch": None, "critic": ["critic"], "high": ["high"], "low": ["low"], "all": ["critic", "high", "low"],
        "all_restarted": ["critic", "high", "low"], "critic_low": ["critic", "low"]}
RESTARTED = {"all_restarted"}


def one(source: str, seed: int, out: Path, steps: int | None, overrides: list[str],
        restart: bool = False, arms: tuple[str, ...] = tuple(ARMS), source_overrides: tuple[str, ...] = ()) -> list[dict]:
    """The source run of one (pair, seed) and the target ``arms``; one result row per arm (``restart``:
    every arm with its schedules started afresh, so ``all_restarted`` is left out). ``source_overrides``
    apply to the source run only, after ``overrides``."""
    import torch

    from hubsgo_ppl.experiments.io import load_checkpoint
    from hubsgo_ppl.experiments.logger import read_csv_rows
    from hubsgo_ppl.experiments.run import RunConfig, resolve, train

    torch.set_num_threads(1)
    target = PAIRS[source]
    base = out / f"{source}-to-{target}" / f"seed{seed}"

    def ensure(run: Path, cfg: RunConfig) -> None:
        budget = int(resolve(cfg)["hyper"]["steps"])
        try:
            done = int(load_checkpoint(run / "checkpoint.pt", mmap=True)["env_steps"]) >= budget
        except Exception:       # noqa: BLE001 - missing or damaged: (re)run it
            done = False
        if not done:
            shutil.rmtree(run, ignore_errors=True)
            train(cfg, run, progress=False)

    src = base / "source"
    ensure(src, RunConfig(task=source, seed=seed, steps=steps, overrides=[*overrides, *source_overrides]))
    rows = []
    for arm, parts in ARMS.items():
        if (restart and arm in RESTARTED) or arm not in arms:
            continue
        run = base / arm
        ensure(run, RunConfig(task=target, seed=seed, steps=steps, overrides=overrides,
                              init_from=None if parts is None else str(src), transfer=parts,
                              restart_schedules=parts is not None and (restart or arm in RESTARTED)))
        metrics = read_csv_rows(run / "metrics.csv")
        last = metrics[-WINDOW:]
        rows.append({"source": source, "target": target, "seed": seed, "arm": arm, "episodes": len(metrics),
                     "steps_to_90": steps_to(metrics),
                     "final_success": sum(float(r["success"]) for r in last) / max(len(last), 1)})
    return rows


def summarise(rows: list[dict], path: Path) -> str:
    return summary_table(rows, lambda r: f"{r['source']} -> {r['target']}", ARMS,
                         ["pair", "arm", "seeds", "steps to 90% success", "success, last 20 episodes"],
                         ["steps_to_90", "final_success"], path,
                         paired=paired_lines(rows, lambda r: f"{r['source']} -> {r['target']}",
                                             [(arm, "scratch") for arm in ARMS if arm != "scratch"], "steps_to_90", "pair"))


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "one seed, keydoor -> keydoor_moved, 1,000 steps, tiny networks")
    p.add_argument("--sources", nargs="+", default=DEFAULT_SOURCES, choices=list(PAIRS),
                   help="the source tasks of the pairs to run (default: %(default)s)")
    p.add_argument("--arms", nargs="+", default=list(ARMS), choices=list(ARMS), help="the target arms to run")
    p.add_argument("--source-set", dest="source_overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="a hyperparameter override for the source runs only, after --set (repeatable), "
                        "e.g. env.start=room")
    p.add_argument("--restart-schedules", action="store_true",
                   help="every transfer arm starts its schedules afresh (`hubsgo train --restart-schedules`)")
    args = p.parse_args(argv)
    overrides: list[str] = list(args.overrides)
    if args.smoke:
        args.sources, args.seeds, args.steps, overrides = ["keydoor"], args.seeds[:1], 1_000, SMOKE + overrides
    out = output_dir(args.out)
    guard_settings(out, "measure_transfer", {"steps": args.steps, "overrides": overrides,
                                             "restart_schedules": args.restart_schedules,
                                             **({"source_overrides": args.source_overrides}
                                                if args.source_overrides else {})})
    jobs = [(s, seed, out, args.steps, overrides, args.restart_schedules, tuple(args.arms),
             tuple(args.source_overrides))
            for s in args.sources for seed in args.seeds]
    return finish(run_jobs(one, jobs, args.workers), out, summarise)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
