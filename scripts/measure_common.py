"""What scripts/measure_revise.py and scripts/measure_transfer.py share: the tiny smoke settings and the
steps-to-success measure."""

from __future__ import annotations

import math

WINDOW = 20
SMOKE = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
         "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def episode_to(rows: list[dict[str, str]], level: float = 0.9, window: int = WINDOW) -> int | None:
    """Index of the first episode whose rolling success rate (``window`` episodes) reaches ``level``."""
    succ = [float(r["success"]) for r in rows]
    for i in range(window - 1, len(succ)):
        if sum(succ[i - window + 1: i + 1]) / window >= level:
            return i
    return None


def steps_to(rows: list[dict[str, str]], level: float = 0.9, window: int = WINDOW) -> float:
    """Env steps at the first episode whose rolling success rate (``window`` episodes) reaches ``level``."""
    i = episode_to(rows, level, window)
    return math.nan if i is None else float(rows[i]["env_steps"])


def run_jobs(one, jobs: list[tuple], workers: int) -> list[dict]:
    """``one(*job)`` for every job (each returns a list of result rows), ``workers`` at a time in spawned
    processes; the rows in job order."""
    rows: list[dict] = []
    if workers > 1 and len(jobs) > 1:
        import multiprocessing as mp
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=mp.get_context("spawn")) as pool:
            for result in pool.map(one, *zip(*jobs)):
                rows += result
    else:
        for job in jobs:
            rows += one(*job)
    return rows


def write_rows(rows: list[dict], path) -> None:
    """The result rows as a CSV, written atomically."""
    import csv
    import io

    from hubsgo_ppl.experiments.io import write_text

    buf = io.StringIO(newline="")
    writer = csv.DictWriter(buf, fieldnames=list(dict.fromkeys(k for r in rows for k in r)), restval="")
    writer.writeheader()
    writer.writerows(rows)
    write_text(path, buf.getvalue())


def parser(doc: str, smoke: str):
    """The options both measurements take: --out, --seeds, --steps, --workers, --set, --smoke."""
    import argparse

    p = argparse.ArgumentParser(description=doc.splitlines()[0])
    p.add_argument("--out", required=True, help="folder of the runs and the results")
    p.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    p.add_argument("--steps", type=int, help="budget of every run (default: the task family's preset)")
    p.add_argument("--workers", type=int, default=2, help="runs of different seeds in parallel")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                   help="a hyperparameter override for every run, as in `hubsgo train --set` (repeatable)")
    p.add_argument("--smoke", action="store_true", help=smoke)
    return p


def mean_se(values) -> tuple[float, float]:
    """Mean and standard error of the finite values (nan, 0 when there are none)."""
    import numpy as np

    v = np.asarray([float(x) for x in values], dtype=float)
    v = v[np.isfinite(v)]
    if not len(v):
        return math.nan, 0.0
    return float(v.mean()), float(v.std(ddof=1) / math.sqrt(len(v))) if len(v) > 1 else 0.0


#: the fields that name a result row's run (a revision's task, a transfer's pair; seed; arm)
ROW_KEYS = ("task", "source", "target", "seed", "arm")


def _row_key(row: dict) -> tuple:
    return tuple("" if row.get(k) is None else str(int(float(row[k])) if k == "seed" else row[k]) for k in ROW_KEYS)


def merged_rows(rows: list[dict], path) -> list[dict]:
    """``rows`` together with the rows of an earlier ``results.csv`` at ``path`` for runs this
    invocation did not measure (other seeds or tasks of the same folder), ordered by run: an
    invocation with ``--seeds 5 6 7 8 9`` adds to the table of seeds 0-4 instead of replacing it."""
    import csv
    from pathlib import Path

    path = Path(path)
    new = {_row_key(r) for r in rows}
    old = []
    if path.is_file():
        with path.open(newline="") as f:
            old = [{**r, "seed": int(float(r["seed"]))} for r in csv.DictReader(f) if _row_key(r) not in new]

    def order(r: dict) -> tuple:
        k = _row_key(r)
        return (k[0], k[1], k[2], int(k[3]) if k[3] else 0)
    return sorted(old + list(rows), key=order)


def finish(rows: list[dict], out, summarise) -> int:
    """Write results.csv (this invocation's rows merged with the earlier ones of other runs,
    :func:`merged_rows`) and summary.md into ``out`` and print the summary."""
    rows = merged_rows(rows, out / "results.csv")
    write_rows(rows, out / "results.csv")
    print(summarise(rows, out / "summary.md"))
    print(f"runs, results.csv and summary.md in {out}")
    return 0


def cell(sel: list[dict], key: str) -> str:
    """``mean ± s.e.`` of ``key`` over the rows ``sel`` (steps, to 90% success or to the first success,
    with thousands separators and how many rows reached it)."""
    m, se = mean_se(r[key] for r in sel)
    if not (key.endswith("steps_to_90") or key == "first_success"):
        return "-" if math.isnan(m) else f"{m:.3f} ± {se:.3f}"
    reached = sum(math.isfinite(float(r[key])) for r in sel)
    return ("-" if math.isnan(m) else f"{m:,.0f} ± {se:,.0f}") + f" ({reached}/{len(sel)} reached)"


def summary_table(rows: list[dict], group, arms, header: list[str], keys: list[str], path,
                  paired: list[str] = ()) -> str:
    """A markdown table, one line per (group, arm) with rows: the group's label (``group(row)``), the arm,
    the number of seeds and ``cell`` of each key, then the table lines ``paired`` (:func:`paired_lines`)
    after a blank line; written atomically to ``path``."""
    from hubsgo_ppl.experiments.io import write_text

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label in dict.fromkeys(group(r) for r in rows):
        for arm in arms:
            sel = [r for r in rows if group(r) == label and r["arm"] == arm]
            if sel:
                lines.append(f"| {label} | {arm} | {len(sel)} | " + " | ".join(cell(sel, k) for k in keys) + " |")
    if paired:
        lines += ["", *paired]
    text = "\n".join(lines) + "\n"
    write_text(path, text)
    return text


def paired_lines(rows: list[dict], group, pairs, key: str, label: str = "") -> list[str]:
    """Markdown table lines comparing two arms seed by seed on ``key`` (steps to 90% success), for each
    ``(arm, other)`` of ``pairs`` per group: the mean ± s.e. of ``arm`` minus ``other`` over the seeds
    where both reached it (negative: ``arm`` sooner), how many of those seeds ``arm`` was sooner, later
    and level in, and the seeds only one of the two reached. ``label`` heads the first column."""
    lines = [f"| {label} | comparison | seeds both reached | first minus second, mean ± s.e. (negative: sooner) "
             "| sooner | later | level | only one reached |", "|" + "---|" * 8]
    for g in dict.fromkeys(group(r) for r in rows):
        by_arm: dict[str, dict[int, float]] = {}
        for r in rows:
            if group(r) == g:
                by_arm.setdefault(r["arm"], {})[int(float(r["seed"]))] = float(r[key])
        for arm, other in pairs:
            mine, theirs = by_arm.get(arm, {}), by_arm.get(other, {})
            seeds = sorted(set(mine) & set(theirs))
            if not seeds:
                continue
            both = [mine[s] - theirs[s] for s in seeds if math.isfinite(mine[s]) and math.isfinite(theirs[s])]
            only = [f"{arm if math.isfinite(mine[s]) else other} in seed {s}" for s in seeds
                    if math.isfinite(mine[s]) != math.isfinite(theirs[s])]
            m, se = mean_se(both)
            diff = "-" if math.isnan(m) else f"{m:,.0f} ± {se:,.0f}"
            lines.append(f"| {g} | {arm} vs {other} | {len(both)} of {len(seeds)} | {diff} | "
                         f"{sum(d < 0 for d in both)} | {sum(d > 0 for d in both)} | {sum(d == 0 for d in both)} | "
                         f"{', '.join(only) or '-'} |")
    return lines


def output_dir(path):
    """``path`` as a Path, created if missing."""
    from pathlib import Path

    out = Path(path)
    out.mkdir(parents=True, exist_ok=True)
    return out


SETTINGS = "settings.json"


class SettingsMismatch(SystemExit):
    """``--out`` holds runs made with other settings: Python prints the one-line message and exits with 1."""


def _as_flags(settings: dict) -> str:
    flags = []
    for key, value in settings.items():
        if key == "overrides":
            flags += [f"--set {v}" for v in value]
        elif key == "source_overrides":
            flags += [f"--source-set {v}" for v in value]
        elif value is True:
            flags.append(f"--{key.replace('_', '-')}")
        elif value not in (None, False):
            flags.append(f"--{key.replace('_', '-')} {value}")
    return " ".join(flags) or "no options"


def guard_settings(out, script: str, settings: dict) -> None:
    """Runs under ``out`` are skipped once finished, whatever made them; so the settings that make a run
    (the budget, the ``--set`` overrides and the script's own switches, not the seeds or the tasks) are
    recorded in ``out/settings.json`` at the first use, and a later call with other settings is refused
    with one line rather than mixing runs of two settings in one table. Seeds and tasks may be added."""
    import json

    from hubsgo_ppl.experiments.io import write_text

    path = out / SETTINGS
    record = {"script": script, **settings}
    if path.exists():
        try:
            before = json.loads(path.read_text())
        except (OSError, ValueError):
            raise SettingsMismatch(f"{script}: {path} is unreadable; remove it if the runs under {out} "
                                   f"were made with {_as_flags(settings)}, or choose another --out") from None
        if before != record:
            before = {k: v for k, v in before.items() if k != "script"} if isinstance(before, dict) else {}
            raise SettingsMismatch(f"{script}: {out} holds runs made with {_as_flags(before)}, not "
                                   f"{_as_flags(settings)}; re-run with those settings or choose another --out")
        return
    write_text(path, json.dumps(record, indent=1) + "\n")
