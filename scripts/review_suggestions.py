"""What one review and its suggested spec do to G* where the spec ties nothing together.

For every HUBS-GO run of a sweep folder (``sweeps/independent_review.yaml``: the critic without any
edge), on a copy of the finished run: ``hubsgo review`` (no GIF), then ``hubsgo revise COPY --model
COPY/review/suggested_spec.yaml --no-train``, which keeps the run finished and reads G* again from the
same recent successes under the revised spec. No env step is taken, so the review's suggestions alone
decide the difference. Per task, mean ± s.e. over the seeds found: whether G*'s top set is exactly one
route (``critic_report.consistent``) before and after, and its probability; per run, the positive
edges the review suggested.

    python scripts/review_suggestions.py runs/sweeps/independent [--out runs/independent_reviewed]

The copies go under ``--out`` (default: the sweep folder's name plus ``_reviewed``); a copy that
already holds a revision is read, not revised again.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import shutil
from pathlib import Path

from critic_report import consistent  # a sibling script module
from measure_common import mean_se

from hubsgo_ppl.diagnostics.review import review
from hubsgo_ppl.experiments.revise import apply_revision


def _ms(values) -> str:
    m, se = mean_se(values)
    return f"{m:.3f} ± {se:.3f}"


def _top(run: Path) -> tuple[set[str], float]:
    table = json.loads((run / "subgoals.json").read_text())
    first = table["ranking"][0]
    return set(first["subgoals"]), float(first["prob"])


def one(run: Path, copy: Path) -> dict:
    if not (copy / "revisions.csv").exists():
        shutil.rmtree(copy, ignore_errors=True)
        shutil.copytree(run, copy, ignore=shutil.ignore_patterns("review", "tb"))
        with contextlib.redirect_stderr(io.StringIO()):
            review(copy, gif=False)
            apply_revision(copy, copy / "review" / "suggested_spec.yaml", train_after=False)
    links = json.loads((copy / "review" / "review.json").read_text()).get("suggested_links", [])
    before, p_before = _top(run)
    after, p_after = _top(copy)
    return {"before": before, "p_before": p_before, "after": after, "p_after": p_after,
            "links": [f"{c['u']}--{c['v']}" for c in links]}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("sweep_dir")
    ap.add_argument("--out")
    args = ap.parse_args()
    root = Path(args.sweep_dir)
    out = Path(args.out) if args.out else root.with_name(root.name + "_reviewed")
    print("| maze | seeds | G* one route: before | after | p(top): before | after | G* after (seeds) |")
    print("|---|---|---|---|---|---|---|")
    detail = []
    for task_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        for var_dir in sorted(p for p in task_dir.iterdir() if p.is_dir() and p.name.startswith("hubsgo")):
            rows = []
            for run in sorted(var_dir.glob("seed*")):
                if (run / "subgoals.json").exists():
                    rows.append((run.name, one(run, out / task_dir.name / var_dir.name / run.name)))
            if not rows:
                continue
            t = task_dir.name
            ok_b = sum(bool(consistent(t, r["before"])) for _, r in rows)
            ok_a = sum(bool(consistent(t, r["after"])) for _, r in rows)
            sets: dict[str, int] = {}
            for _, r in rows:
                key = "{" + ", ".join(sorted(r["after"])) + "}"
                sets[key] = sets.get(key, 0) + 1
            print(f"| {t} ({var_dir.name}) | {len(rows)} | {ok_b}/{len(rows)} | {ok_a}/{len(rows)} | "
                  f"{_ms([r['p_before'] for _, r in rows])} | {_ms([r['p_after'] for _, r in rows])} | "
                  + "; ".join(f"{k} {v}" for k, v in sets.items()) + " |")
            detail += [f"- {t} {seed}: before {{{', '.join(sorted(r['before']))}}} {r['p_before']:.3f}; links suggested "
                       f"{', '.join(r['links']) or 'nothing'}; after {{{', '.join(sorted(r['after']))}}} "
                       f"{r['p_after']:.3f}" for seed, r in rows]
    print()
    print("\n".join(detail))


if __name__ == "__main__":
    main()
