"""Measure what a mid-run revision of the critic spec is worth (``hubsgo review`` + ``hubsgo revise``).

A sweep file cannot express this (a revision happens in the middle of a run, after a review), so this
script runs it. For each task with misleading sub-goals and each seed, at the task's budget B:

- ``revised``: train with the task's built-in spec (``<task>-specific``), pause at B/3, review the
  critic, write the corrected spec (drop every suggested sub-goal that fewer than half of the recent
  successes achieved, with its edges; give each flagged edge its learned sign; with ``--unlink-held``
  also remove the positive edges that the review says hold a sub-goal in G* which most successes
  skipped; with ``--unlink-together`` also remove the negative edges whose two sub-goals every recent
  success achieved; with ``--suggested`` the corrected spec is instead the review's own
  ``suggested_spec.yaml``, which drops nothing before the critic's first update), revise, continue to B;
- ``unrevised``: the same paused run (a copy taken before the revision) continued to B as it was;
- ``restart``: a run from scratch with the corrected spec of the same seed, budget B.

Per arm it reports, as mean ± standard error over the seeds: the success rate over the last 20
episodes, the mean return over the last third of the budget, and the env steps until the rolling
success rate (20 episodes) first reaches 90% (runs that never reach it are counted, not averaged), in
the arm's own run and in total: a restart begins where the other two arms paused, so its total adds
the B/3 steps spent before the pause; the env step of the first success in the arm's own run; and
at the end of each run whether G*'s top set is exactly one route (``critic_report.consistent``) and
its probability.
For the revised and unrevised arms also the failed episodes that began after the pause and the mean
length of the 20th to 60th of those episodes. A second table pairs the seeds: the revised arm's total
steps to 90% success minus the unrevised arm's and the restart's, as mean ± s.e. over the seeds where
both reached it, with the seeds it was sooner, later and level in.
Everything goes under ``--out``: one folder per task, seed and arm, ``results.csv`` (one row per run)
and ``summary.md``. Re-running skips finished runs (the runs are ordinary run directories), so ``--out``
remembers its settings (``settings.json``: ``--steps``, ``--set``, ``--threshold``, ``--keep-linked``,
and ``--unlink-held``, ``--unlink-together``, ``--drop-held``, ``--model`` and ``--suggested`` where
given) and refuses other ones; more seeds or tasks may be added.

    .venv/bin/python scripts/measure_revise.py --out runs/measure_revise            # 2 tasks x 5 seeds, 40,000 steps
    .venv/bin/python scripts/measure_revise.py --out runs/smoke_revise --smoke        # a pipeline check in a minute

``--smoke``: one seed, keydoor_incorrect only, 1,500 steps and tiny networks; it checks that the
pipeline runs, and measures nothing.
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path
from typing import Any
from measure_common import (SMOKE, WINDOW, finish, guard_settings, output_dir, paired_lines, parser, run_jobs,  # noqa: E402
                            steps_to, summary_table)  # noqa: E402  (a sibling script module)

ROOT = Path(__file__).resolve().parents[1]
TASKS = ("keydoor_incorrect", "fourroom_incorrect")
ARMS = ("revised", "unrevised", "restart")


def run_stats(run: Path, budget: int, pause: int | None = None) -> dict[str, float]:
    """Per-run measures; with ``pause`` (the env step of the review) also the failed episodes after it
    and the mean length of the 20th to 60th episode after it."""
    from hubsgo_ppl.experiments.logger import read_csv_rows

    rows = read_csv_rows(run / "metrics.csv")
    last = rows[-WINDOW:]
    tail = [r for r in rows if float(r["env_steps"]) > budget * 2 / 3] or rows[-1:]
    out = {"episodes": len(rows), "final_success": sum(float(r["success"]) for r in last) / max(len(last), 1),
           "late_return": sum(float(r["return"]) for r in tail) / max(len(tail), 1),
           "steps_to_90": steps_to(rows),
           "first_success": next((float(r["env_steps"]) for r in rows if float(r["success"])), float("nan"))}
    out["failures_after_pause"] = out["settled_length"] = float("nan")
    if pause is not None:
        after = [r for r in rows if float(r["env_steps"]) - float(r["length"]) >= pause]
        settled = after[20:60]
        out["failures_after_pause"] = float(sum(1 for r in after if not float(r["success"])))
        out["settled_length"] = (sum(float(r["length"]) for r in settled) / len(settled)) if settled else float("nan")
    return out


def corrected_spec(review: dict[str, Any], spec: dict[str, Any], path: Path, keep_linked: bool = False,
                   unlink_held: bool = False, unlink_together: bool = False, drop_held: bool = False) -> Path:
    """The human's revision of ``spec`` after ``review`` (module docstring), written to ``path``.
    ``keep_linked``: a human who drops only suggested sub-goals that no edge of the spec joins to
    another sub-goal (the route not taken stays; sub-goals the human related to nothing go).
    ``unlink_held``: a human who also removes the positive edges that hold a sub-goal in G* though
    most recent successes skipped it (``review["held_by_edges"]``); the sub-goal stays a candidate.
    ``unlink_together``: a human who also removes the negative edges whose two sub-goals most recent
    successes both achieved (``review["negative_edges_achieved_together"]``).
    ``drop_held``: a human who drops the sub-goals that the review says positive edges hold in G*, or
    above the drop threshold, though most recent successes skipped them (``review["held_by_edges"]``
    and ``review["held_up_by_edges"]``), with their edges."""

    linked = {n for u, v, _ in spec["edges"] for n in (u, v)}
    drop = {d["name"] for d in review["suggested_drops"]
            if (d["success_frequency"] is None or d["success_frequency"] < 0.5)
            and not (keep_linked and d["name"] in linked)}
    if drop_held:
        drop |= {d["name"] for d in review.get("held_by_edges", []) + review.get("held_up_by_edges", [])}
    keep = [n for n in spec["subgoals"] if n not in drop]
    if not keep:                                    # a spec lists at least one sub-goal
        keep, drop = list(spec["subgoals"]), set()
    flip = {frozenset((c["u"], c["v"])): c["learned"] for c in review["flagged_edges"]}
    held = review.get("held_by_edges", []) if unlink_held else []
    unlink = {frozenset((d["name"], v)) for d in held for v in d["positive_edges"]}
    if unlink_together:
        unlink |= {frozenset((c["u"], c["v"])) for c in review.get("negative_edges_achieved_together", [])}
    new = dict(spec, name=f"{spec['name']}-revised", subgoals=keep,
               edges=[[u, v, flip.get(frozenset((u, v)), s)] for u, v, s in spec["edges"]
                      if u not in drop and v not in drop and frozenset((u, v)) not in unlink])
    from hubsgo_ppl.experiments.io import write_yaml

    write_yaml(path, new)
    return path


def g_star(run: Path, task: str) -> dict[str, float]:
    """Whether the run's final G* top set (``subgoals.json``) is exactly one route (1.0 or 0.0; NaN
    where the task's routes are not known) and its probability."""
    import json

    from critic_report import consistent

    top = json.loads((run / "subgoals.json").read_text())["ranking"][0]
    ok = consistent(task, set(top["subgoals"]))
    return {"g_star_one_route": float("nan") if ok is None else float(ok), "g_star_p": float(top["prob"])}


def one(task: str, seed: int, out: Path, steps: int | None, overrides: list[str], threshold: float,
        keep_linked: bool = False, unlink_held: bool = False, unlink_together: bool = False,
        model: str | None = None, drop_held: bool = False, suggested: bool = False) -> list[dict]:
    """The three arms of one (task, seed); returns one result row per arm."""
    import torch
    import yaml

    from hubsgo_ppl.diagnostics.review import review, suggested_spec
    from hubsgo_ppl.experiments.io import load_checkpoint, write_yaml
    from hubsgo_ppl.experiments.revise import revise
    from hubsgo_ppl.experiments.run import RunConfig, resolve, train

    torch.set_num_threads(1)
    base = out / task / f"seed{seed}"
    budget = int(resolve(RunConfig(task=task, steps=steps, overrides=overrides))["hyper"]["steps"])
    runs = {arm: base / arm for arm in ARMS}

    def finished(run: Path) -> bool:
        try:
            return int(load_checkpoint(run / "checkpoint.pt", mmap=True)["env_steps"]) >= budget
        except Exception:       # noqa: BLE001 - missing or damaged: (re)run it
            return False

    spec_path = base / "corrected.yaml"
    if not (finished(runs["revised"]) and finished(runs["unrevised"]) and spec_path.exists()):
        for arm in ("revised", "unrevised"):
            shutil.rmtree(runs[arm], ignore_errors=True)
        cfg = RunConfig(task=task, seed=seed, steps=steps, overrides=overrides,
                        model=None if model is None else str(ROOT / model.format(task=task)))
        train(cfg, runs["revised"], progress=False, stop_at=max(1, budget // 3))
        shutil.copytree(runs["revised"], runs["unrevised"])
        r = review(runs["revised"], threshold=threshold, gif=False, num_samples=2_000)
        spec = load_checkpoint(runs["revised"] / "checkpoint.pt")["config"]["model_spec"]
        if suggested:           # the human revises with the review's suggested_spec.yaml as written
            write_yaml(spec_path, suggested_spec(r, spec))
        else:
            corrected_spec(r, spec, spec_path, keep_linked, unlink_held, unlink_together, drop_held)
        revise(runs["revised"], spec_path, progress=False)
        train(RunConfig(task=task), runs["unrevised"], resume=True, progress=False)
    if not finished(runs["restart"]):
        shutil.rmtree(runs["restart"], ignore_errors=True)
        train(RunConfig(task=task, seed=seed, steps=steps, model=str(spec_path), overrides=overrides),
              runs["restart"], progress=False)
    dropped = [n for n in yaml.safe_load((runs["revised"] / "revisions" / "001" / "spec_before.yaml").read_text())["subgoals"]
               if n not in yaml.safe_load(spec_path.read_text())["subgoals"]]
    rows = [{"task": task, "seed": seed, "arm": arm, "budget": budget, "dropped": " ".join(dropped),
             **run_stats(runs[arm], budget, None if arm == "restart" else budget // 3), **g_star(runs[arm], task)}
            for arm in ARMS]
    for row in rows:    # total env steps: a restart begins where the other two arms paused
        row["total_steps_to_90"] = row["steps_to_90"] + (budget // 3 if row["arm"] == "restart" else 0)
    return rows


def summarise(rows: list[dict], path: Path) -> str:
    return summary_table(rows, lambda r: r["task"], ARMS,
                         ["task", "arm", "seeds", "success, last 20 episodes", "return, last third",
                          "steps to 90% success (own run)", "total env steps to 90% success",
                          "first success (own run)", "failed episodes after B/3",
                          "length of the 20th-60th episode after B/3", "G* one route (share of seeds)",
                          "p(top)"],
                         ["final_success", "late_return", "steps_to_90", "total_steps_to_90", "first_success",
                          "failures_after_pause", "settled_length", "g_star_one_route", "g_star_p"], path,
                         paired=paired_lines(rows, lambda r: r["task"], [("revised", "unrevised"), ("revised", "restart")],
                                             "total_steps_to_90", "task"))


def main(argv: list[str] | None = None) -> int:
    p = parser(__doc__, "one seed, keydoor_incorrect, 1,500 steps, tiny networks")
    p.add_argument("--tasks", nargs="+", default=list(TASKS))
    p.add_argument("--threshold", type=float, default=0.2, help="the review's drop threshold")
    p.add_argument("--keep-linked", action="store_true",
                   help="drop only suggested sub-goals that no edge of the spec joins to another one")
    p.add_argument("--unlink-held", action="store_true",
                   help="also remove the positive edges that hold a sub-goal in G* which most successes skipped")
    p.add_argument("--unlink-together", action="store_true",
                   help="also remove the negative edges whose two sub-goals every recent success achieved")
    p.add_argument("--drop-held", action="store_true",
                   help="also drop the sub-goals positive edges hold in G* though most successes skipped them")
    p.add_argument("--suggested", action="store_true",
                   help="revise with the review's own suggested_spec.yaml (what review.md tells a user to pass to "
                        "`hubsgo revise`) instead of the protocol's corrected spec; the other protocol options do not apply")
    p.add_argument("--model", help="the spec the run starts from, a path from the repository root with {task} "
                                   "(default: each task's built-in <task>-specific)")
    args = p.parse_args(argv)
    overrides: list[str] = list(args.overrides)
    if args.smoke:
        args.tasks, args.seeds, args.steps, overrides = ["keydoor_incorrect"], args.seeds[:1], 1_500, SMOKE + overrides
    out = output_dir(args.out)
    settings = {"steps": args.steps, "overrides": overrides, "threshold": args.threshold, "keep_linked": args.keep_linked}
    if args.unlink_held:            # recorded only where given: folders made before the option still match
        settings["unlink_held"] = True
    if args.unlink_together:
        settings["unlink_together"] = True
    if args.drop_held:
        settings["drop_held"] = True
    if args.model:
        settings["model"] = args.model
    if args.suggested:
        if args.keep_linked or args.unlink_held or args.unlink_together or args.drop_held:
            p.error("--suggested revises with the review's suggested spec; --keep-linked, --unlink-held, "
                    "--unlink-together and --drop-held do not apply to it")
        settings["suggested"] = True
    guard_settings(out, "measure_revise", settings)
    jobs = [(t, s, out, args.steps, overrides, args.threshold, args.keep_linked, args.unlink_held, args.unlink_together,
             args.model, args.drop_held, args.suggested)
            for t in args.tasks for s in args.seeds]
    return finish(run_jobs(one, jobs, args.workers), out, summarise)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
