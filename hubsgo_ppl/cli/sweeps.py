"""The commands over grids of runs: ``hubsgo sweep`` and ``hubsgo report``."""

from __future__ import annotations

import argparse
import sys

__all__ = ["cmd_sweep", "cmd_report"]


def cmd_sweep(args: argparse.Namespace) -> int:
    from ..experiments.sweep import run_sweep

    result = run_sweep(args.sweep, backend=args.backend, workers=args.workers, out=args.out,
                       progress=not args.no_progress, variants=args.variants, tasks=args.tasks)
    print(f"sweep {result['sweep_dir']}: {result['finished']} finished, {result['skipped']} skipped "
          f"(already done), {result['retried']} retried, {len(result['failed'])} failed")
    for f in result["failed"]:
        print(f"  failed: {f}")
    if any(status == "refused" for status in result["runs"].values()):
        return 2            # a run folder train refuses: the user's to fix, as `hubsgo train` says it
    return 1 if result["failed"] else 0


def cmd_report(args: argparse.Namespace) -> int:
    from ..experiments.report import write_report

    notes: list[str] = []
    paths = write_report(args.sweep_dir, out=args.out, sweep=args.sweep, notes=notes)
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    for note in notes:
        print(f"hubsgo report: {note}", file=sys.stderr)
    return 0
