"""The sweep report: the paper's Tables 1 and 2, learning curves (Figs. 6, 7, 9) and a CSV of every number.

Statistic (as in the paper's tables): for each run, the **average episodic return over training** (the
mean of ``return`` over every row of its ``metrics.csv``); for each (variant, task) cell, the mean of
those averages across seeds ± their standard error ``std(ddof=1) / sqrt(n)``.

Curves: each run's episodes are binned by ``env_steps`` (``bins`` equal bins up to the task's largest
step count); a run's value in a bin is the mean return of its episodes ending there (carried forward
through bins where no episode ended); the band is ± one standard error across seeds.

Beside it, the success table: for each run the **env steps until 90% success** (the first episode end
at which the success rate over the last ``SUCCESS_WINDOW`` episodes reaches 0.9), the **success rate over
the last 10% of the budget** (episodes ending in the last tenth of the run's env steps) and, for runs with
a critic, **G*** (the most probable set of ``subgoals.json``); per cell, the steps as mean ± s.e. over the
seeds that got there with how many did, the success rate as mean ± s.e. over every seed, and each G*
with the number of seeds that read it.

Both are pandas group-bys: runs by (variant, task) for the tables, episodes by ``pd.cut`` bin for a
run's curve (then ``reindex``/``ffill``), and a bins x runs frame's row mean/std for the band.
"""

from __future__ import annotations

import csv
import io
import math
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from ..errors import ReportError
from .checkpoint import checkpoint_env_steps, read_config_file
from .io import atomic_write, write_text
from .logger import read_csv_rows
from .paper import PAPER

__all__ = ["ReportError", "RunSummary", "Cell", "PAPER", "SUCCESS_WINDOW", "collect", "aggregate", "markdown_table",
           "steps_to_success", "success_table", "curves", "write_report"]

#: episodes in the rolling success rate of "steps until 90% success" (the loop's ``outcome_window``)
SUCCESS_WINDOW = 20


@dataclass
class RunSummary:
    task: str
    variant: str
    seed: int
    episodes: int
    env_steps: int
    avg_return: float
    final_return: float          # mean return over the last 10% of episodes
    success_rate: float
    steps: np.ndarray            # per episode
    returns: np.ndarray
    successes: np.ndarray | None = None     # per episode, 0/1
    g_star: tuple[str, ...] | None = None   # the most probable set of subgoals.json, where the run has one
    budget: int | None = None               # the env-step budget its config.yaml records (None: no config.yaml)
    spent: int | None = None                # env steps its checkpoint records (None: none readable)
    settings: str | None = None             # what it trained with but for seed and budget (sweep.settings_key)

    @property
    def done(self) -> int:
        """Env steps trained: the checkpoint's count (a flat agent stops mid-episode, past the last row)."""
        return self.env_steps if self.spent is None else self.spent

    @property
    def finished(self) -> bool:
        """Whether the run has spent its budget (as `hubsgo sweep` decides it); one without a recorded budget counts."""
        return self.budget is None or self.done >= self.budget


def steps_to_success(steps: np.ndarray, successes: np.ndarray, rate: float = 0.9,
                     window: int = SUCCESS_WINDOW) -> int | None:
    """Env steps at the first episode end where the success rate of the last ``window`` episodes is at
    least ``rate`` (None if it never is; fewer than ``window`` episodes never count)."""
    s = np.asarray(successes, dtype=float)
    if len(s) < window:
        return None
    rolling = np.convolve(s, np.ones(window), "valid") / window     # rolling[i] ends at episode i + window - 1
    hit = np.flatnonzero(rolling >= rate - 1e-12)
    return None if hit.size == 0 else int(steps[hit[0] + window - 1])


def _late_success(r: "RunSummary") -> float:
    """Success rate of the episodes ending in the last 10% of the run's env steps (its last episode if none)."""
    late = r.steps >= 0.9 * r.steps[-1]
    return float(np.mean(r.successes[late])) if late.any() else float(r.successes[-1])


def _g_star(run: Path) -> tuple[str, ...] | None:
    path = run / "subgoals.json"
    if not path.is_file():
        return None
    try:
        import json

        ranking = json.loads(path.read_text(encoding="utf-8"))["ranking"]
        return tuple(ranking[0]["subgoals"]) if ranking else None
    except (ValueError, KeyError, IndexError, TypeError):
        return None


@dataclass
class Cell:
    task: str
    variant: str
    n: int
    mean: float
    se: float                    # nan when n < 2


def _layout(sweep_dir: Path) -> tuple[list[str], list[str], dict[str, str], str | None]:
    """(tasks, variants, labels, table) from ``sweep.yaml`` if present, else from the folder tree."""
    meta = sweep_dir / "sweep.yaml"
    if meta.is_file():
        from .sweep import column_folder

        try:
            spec = yaml.safe_load(meta.read_text(encoding="utf-8"))
            tasks = [column_folder(t["name"]) for t in spec["tasks"]]
            variants = [v["name"] for v in spec["variants"]]
            labels = {v["name"]: v.get("label") or v["name"] for v in spec["variants"]}
            return tasks, variants, labels, spec.get("table")
        except (yaml.YAMLError, UnicodeDecodeError, TypeError, KeyError, AttributeError) as exc:
            raise ReportError(f"{meta}: not the sweep file `hubsgo sweep` writes ({type(exc).__name__}: "
                              f"{' '.join(str(exc).split())}); delete it to report the folder's runs as found, "
                              "or pass --sweep SWEEP.yaml") from None
    tasks = sorted(p.name for p in sweep_dir.iterdir() if p.is_dir() and p.name != "report")
    variants = sorted({v.name for t in tasks for v in (sweep_dir / t).iterdir() if v.is_dir()})
    return tasks, variants, {v: v for v in variants}, None


def collect(sweep_dir: str | Path) -> list[RunSummary]:
    """Every run with a non-empty ``metrics.csv`` under ``SWEEP_DIR/<task>/<variant>/seed<k>``."""
    from .sweep import settings_key

    sweep_dir, out = Path(sweep_dir), []
    for metrics in sorted(sweep_dir.glob("*/*/seed*/metrics.csv")):
        run = metrics.parent
        rows = read_csv_rows(metrics)     # a file that is no CSV log: RunFileError, one line
        rows = [r for r in rows if None not in r.values() and "" not in (r.get("return"), r.get("env_steps"))]
        if not rows:        # (a row cut short by a kill mid-write is left out, as --resume cuts it)
            continue
        try:
            rets = np.array([float(r["return"]) for r in rows])
            steps = np.array([float(r["env_steps"]) for r in rows])
            succ = np.array([float(r["success"]) for r in rows])
            seed = int(run.name[len("seed"):])
        except (KeyError, ValueError) as exc:
            raise ReportError(f"{metrics}: not a metrics file of `hubsgo train` ({exc}); "
                             "expected columns episode, env_steps, return, success") from None
        tail = rets[-max(1, len(rets) // 10):]
        out.append(RunSummary(run.parent.parent.name, run.parent.name, seed, len(rows), int(steps[-1]),
                              float(rets.mean()), float(tail.mean()), float(succ.mean()), steps, rets, succ,
                              _g_star(run), _budget(run), checkpoint_env_steps(run), settings_key(run)))
    return out


def _budget(run: Path) -> int | None:
    """The env-step budget ``run/config.yaml`` records, or None where it records none."""
    steps = ((read_config_file(run) or {}).get("hyper") or {}).get("steps")
    return int(steps) if isinstance(steps, (int, float)) and not isinstance(steps, bool) else None


def aggregate(runs: list[RunSummary]) -> dict[tuple[str, str], Cell]:
    """(variant, task) -> mean ± s.e. across seeds of the per-run average returns."""
    if not runs:
        return {}
    df = pd.DataFrame({"variant": [r.variant for r in runs], "task": [r.task for r in runs],
                       "avg_return": [r.avg_return for r in runs]})
    # Series.mean/std per group: numpy's two-pass sums, so the cells are bit-for-bit the hand computation
    # (groupby's built-in "mean"/"std" use compensated and online sums, which differ in the last bit).
    stats = df.groupby(["variant", "task"], sort=False)["avg_return"].agg(
        count="count", mean=pd.Series.mean, std=pd.Series.std)
    se = stats["std"] / np.sqrt(stats["count"])           # std(ddof=1) is NaN for a single seed
    return {(v, t): Cell(t, v, int(row["count"]), float(row["mean"]), float(se[(v, t)]))
            for (v, t), row in stats.iterrows()}


def _fmt(mean: float, se: float) -> str:
    return f"{mean:.4f} ± {se:.4f}" if math.isfinite(se) else f"{mean:.4f} (n=1)"


def markdown_table(cells: dict[tuple[str, str], Cell], tasks: list[str], variants: list[str],
                   labels: dict[str, str], title: str) -> str:
    lines = [f"**{title}**", "", "| Algorithm | " + " | ".join(tasks) + " |",
             "|---|" + "---|" * len(tasks)]
    for v in variants:
        row = [_fmt(cells[(v, t)].mean, cells[(v, t)].se) if (v, t) in cells else "-" for t in tasks]
        if any(c != "-" for c in row):
            lines.append(f"| {labels.get(v, v)} | " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def success_table(runs: list[RunSummary], tasks: list[str], variants: list[str], labels: dict[str, str]) -> str:
    """The success table (module docstring): one row per (task, variant) with runs."""
    lines = ["**Steps until 90% success, success over the last 10% of the budget, and G\\***", "",
             f"Steps: mean ± s.e. over the seeds whose rolling success ({SUCCESS_WINDOW} episodes) reached 0.9, "
             "with how many of the seeds did. G*: each set read, with its number of seeds.", "",
             "| task | Algorithm | steps to 90% | seeds at 90% | success, last 10% | G* |", "|---|---|---|---|---|---|"]
    for t in tasks:
        for v in variants:
            mine = [r for r in runs if r.task == t and r.variant == v and r.successes is not None]
            if not mine:
                continue
            hits = [s for s in (steps_to_success(r.steps, r.successes) for r in mine) if s is not None]
            late = np.array([_late_success(r) for r in mine])
            reached = "-" if not hits else (f"{np.mean(hits):,.0f}" + (f" ± {np.std(hits, ddof=1) / np.sqrt(len(hits)):,.0f}"
                                                                       if len(hits) > 1 else ""))
            se = late.std(ddof=1) / np.sqrt(len(late)) if len(late) > 1 else float("nan")
            sets: dict[tuple[str, ...], int] = {}
            for r in mine:
                if r.g_star is not None:
                    sets[r.g_star] = sets.get(r.g_star, 0) + 1
            g = "; ".join(f"{{{', '.join(k)}}} {n}/{len(mine)}" for k, n in sorted(sets.items(), key=lambda kv: -kv[1]))
            lines.append(f"| {t} | {labels.get(v, v)} | {reached} | {len(hits)}/{len(mine)} | "
                         f"{_fmt(float(late.mean()), float(se))} | {g or '-'} |")
    return "\n".join(lines) + "\n"


def _paper_table(table: str, tasks: list[str], variants: list[str], labels: dict[str, str]) -> str:
    ref = PAPER[table]
    lines = [f"**The paper's {table.replace('table', 'Table ')} (same rows and columns)**", "",
             "| Algorithm | " + " | ".join(tasks) + " |", "|---|" + "---|" * len(tasks)]
    for v in variants:
        label = labels.get(v, v)
        if label in ref:
            lines.append(f"| {label} | " + " | ".join(_fmt(*ref[label][t]) if t in ref[label] else "-"
                                                     for t in tasks) + " |")
    return "\n".join(lines) + "\n"


def _binned(run: RunSummary, edges: np.ndarray) -> pd.Series:
    """One run's curve: the mean return of its episodes ending in each ``env_steps`` bin (bins closed on
    the right, the first also on the left), carried forward through bins where no episode ended; NaN
    before its first episode. (pandas sums a bin with compensation: a bin of many episodes can differ
    from a plain left-to-right sum in the last bit.)"""
    bins = len(edges) - 1
    idx = pd.cut(run.steps, edges, labels=False, include_lowest=True, duplicates="drop")
    idx = np.nan_to_num(idx, nan=0.0).astype(int)     # outside the edges (all steps 0): the first bin
    means = pd.Series(run.returns).groupby(idx).mean()
    return means.reindex(range(bins)).ffill()


def curves(runs: list[RunSummary], task: str, variants: list[str], bins: int = 40
           ) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """variant -> (bin centres, mean, s.e.) of the binned learning curves on ``task``; the s.e. is NaN in a
    bin where fewer than two runs have a value (one run's curve has no spread to show)."""
    mine = [r for r in runs if r.task == task]
    if not mine:
        return {}
    hi = max(r.steps.max() for r in mine)
    edges = np.linspace(0.0, hi, bins + 1)
    centres = (edges[:-1] + edges[1:]) / 2
    out = {}
    for v in variants:
        per_run = [_binned(r, edges) for r in mine if r.variant == v]
        if not per_run:
            continue
        table = pd.concat(per_run, axis=1, ignore_index=True)    # bins x runs
        n = table.count(axis=1)
        mean = table.mean(axis=1)                               # NaN where no run has a value yet
        se = (table.std(axis=1, ddof=1) / np.sqrt(n)).where(n > 1, np.nan)
        out[v] = (centres, mean.to_numpy(), se.to_numpy())
    return out


def _plot(task: str, data: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], labels: dict[str, str],
          path: Path) -> Path:
    from matplotlib.figure import Figure   # no pyplot: leaves the caller's backend alone

    fig = Figure(figsize=(9, 4))
    ax = fig.subplots()
    for i, (v, (x, m, se)) in enumerate(data.items()):
        ax.plot(x, m, color=f"C{i % 10}", lw=1.8, label=labels.get(v, v))
        ax.fill_between(x, m - se, m + se, color=f"C{i % 10}", alpha=0.2, lw=0)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episodic return")
    ax.set_title(f"{task}: mean ± s.e. across seeds")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))   # beside the axes, off the curves
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    return path


def _csv(rows: list[dict[str, Any]]) -> str:
    fields: list[str] = []
    for r in rows:
        fields += [k for k in r if k not in fields]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=fields)
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _split_budgets(runs: list[RunSummary], grid: dict[tuple[str, str], int]
                   ) -> tuple[list[RunSummary], list[RunSummary]]:
    """(runs at their cell's budget or recording none, runs at another): a cell never mixes budgets."""
    other = [r for r in runs if r.budget is not None and r.budget != grid.get((r.task, r.variant), r.budget)]
    return [r for r in runs if r not in other], other


def _seeds_line(runs: list[RunSummary]) -> str:
    """The seeds behind the cells: one list where every cell has the same, else each cell's."""
    by_cell: dict[tuple[str, str], list[int]] = {}
    for r in runs:
        by_cell.setdefault((r.task, r.variant), []).append(r.seed)
    lists = {key: sorted(seeds) for key, seeds in by_cell.items()}
    if len({tuple(v) for v in lists.values()}) == 1:
        seeds = next(iter(lists.values()))
        return f"Seeds: {', '.join(map(str, seeds))} ({len(seeds)}) in every cell."
    return "Seeds per cell: " + "; ".join(f"{t}/{v}: {', '.join(map(str, s))} ({len(s)})"
                                          for (t, v), s in sorted(lists.items())) + "."


def _nothing_logged(sweep_dir: Path, runs: list[RunSummary], grid: tuple[list[str], list[str], list[int]] | None
                    ) -> list[str]:
    """The run folders ``task/variant/seedK`` without an episode logged (a run starting, or stopped before its
    first episode ended), of the ``grid`` (tasks, variants, seeds) where given."""
    have = {(r.task, r.variant, f"seed{r.seed}") for r in runs}
    keys = [(p.parent.parent.name, p.parent.name, p.name) for p in sorted(sweep_dir.glob("*/*/seed*")) if p.is_dir()]
    return ["/".join(k) for k in keys if k not in have and (grid is None or (
        k[0] in grid[0] and k[1] in grid[1] and k[2] in {f"seed{s}" for s in grid[2]}))]


def write_report(sweep_dir: str | Path, out: str | Path | None = None, bins: int = 40,
                 sweep: str | Path | None = None, notes: list[str] | None = None) -> dict[str, Path]:
    """Write ``results.md`` (tables), ``results.csv`` (per run and aggregated), ``curves.csv`` and one
    ``curve_<task>.png`` per task into ``out`` (default ``SWEEP_DIR/report``). Returns the paths.

    ``sweep`` (a sweep .yaml or built-in name) limits the report to that grid's tasks, variants and
    seeds, for a folder that several sweeps have run into; by default the layout comes from the
    folder's ``sweep.yaml`` (the last sweep run there) and every run found is reported. A run short of
    the budget its ``config.yaml`` records (a sweep still running, or interrupted) is left out of the
    tables and curves, and ``results.md`` names it (as does a line added to ``notes``, where given); so is
    a run trained at another budget than its cell's (the grid's, or without ``sweep`` the one most of the
    cell's runs record).
    """
    sweep_dir = Path(sweep_dir)
    if not sweep_dir.is_dir():
        raise ReportError(f"{sweep_dir}: no such sweep directory; pass the --out folder of `hubsgo sweep`")
    runs = collect(sweep_dir)
    empty = _nothing_logged(sweep_dir, runs, None)
    if sweep is not None:
        from .sweep import column_folder, load_sweep

        spec, _ = load_sweep(sweep)
        tasks, variants = [column_folder(t.name) for t in spec.tasks], [v.name for v in spec.variants]
        labels = {v.name: v.label or v.name for v in spec.variants}
        table = spec.table
        runs = [r for r in runs if r.task in tasks and r.variant in variants and r.seed in spec.seeds]
        empty = _nothing_logged(sweep_dir, runs, (tasks, variants, spec.seeds))
        grid = {(column_folder(t.name), v.name): v.steps or t.steps for t in spec.tasks for v in spec.variants}
        runs, other = _split_budgets(runs, grid)
    from .sweep import split_settings

    unfinished = [r for r in runs if not r.finished]     # a sweep still running, or stopped: not in the tables
    runs = [r for r in runs if r.finished]
    if sweep is None:   # each cell's budget: the one most of its finished runs record (the larger on a tie)
        counts = Counter((r.task, r.variant, r.budget) for r in runs if r.budget is not None)
        runs, other = _split_budgets(runs, {(t, v): b for (t, v, b), _ in sorted(
            counts.items(), key=lambda kv: (kv[1], kv[0][2]))})
    runs, mixed = split_settings(runs)      # nor settings: a sweep file edited between calls, runs moved in
    if not runs:
        raise ReportError(f"{sweep_dir}: no finished runs (expected <task>/<variant>/seed<k>/metrics.csv)"
                          f"{' of the grid ' + str(sweep) if sweep is not None else ''}"
                          f"{f', {len(unfinished)} still short of their budget' if unfinished else ''}"
                          f"{f', {len(other)} trained at another budget than their cell' if other else ''}; "
                          "run `hubsgo sweep` (again) first")
    if sweep is None:
        tasks, variants, labels, table = _layout(sweep_dir)
        tasks += sorted({r.task for r in runs} - set(tasks))
        variants += sorted({r.variant for r in runs} - set(variants))
    out = Path(out) if out is not None else sweep_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    cells = aggregate(runs)
    title = {"table1": "Table 1", "table2": "Table 2"}.get(table or "", "Table")
    md = [f"# Report of sweep `{sweep_dir}`", "",
          "Cell: the average episodic return over training of each run, then mean ± standard error "
          f"across seeds. {_seeds_line(runs)}", "", markdown_table(cells, tasks, variants, labels,
                                                                  f"{title}: this sweep")]
    if table in PAPER:
        md += ["", _paper_table(table, tasks, variants, labels)]
    md += ["", success_table(runs, tasks, variants, labels)]
    if unfinished and notes is not None:
        notes.append(f"left out {len(unfinished)} run(s) short of their budget (results.md names them); "
                     "`hubsgo sweep` with the same arguments finishes them")
    if unfinished:
        md += ["", f"Left out, short of their budget ({len(unfinished)}; `hubsgo sweep` again finishes them): "
               + ", ".join(f"{r.task}/{r.variant}/seed{r.seed} at {r.done:,} of {r.budget:,} env steps"
                           for r in sorted(unfinished, key=lambda r: (r.task, r.variant, r.seed))) + "."]
    if empty:
        md += ["", f"Left out, no episode logged yet ({len(empty)}; a run starting, or stopped before its first "
               f"episode ended): {', '.join(empty)}."]
        if notes is not None:
            notes.append(f"left out {len(empty)} run(s) with no episode logged yet (results.md names them)")
    if other:
        what = ", ".join(f"{r.task}/{r.variant}/seed{r.seed} at {r.budget:,}" for r in
                         sorted(other, key=lambda r: (r.task, r.variant, r.seed)))
        md += ["", f"Left out, trained at another budget than their cell's ({len(other)}): {what} env steps."]
        if notes is not None:
            notes.append(f"left out {len(other)} run(s) trained at another budget than their cell's (results.md "
                         "names them); a cell never mixes budgets")
    if mixed:
        md += ["", f"Left out, trained with other settings than their cell's runs ({len(mixed)}): "
               + ", ".join(sorted(f"{r.task}/{r.variant}/seed{r.seed}" for r in mixed)) + "."]
        if notes is not None:
            notes.append(f"left out {len(mixed)} run(s) trained with other settings than their cell's runs")
    paths: dict[str, Path] = {"table": write_text(out / "results.md", "\n".join(md))}

    rows: list[dict[str, Any]] = []
    for r in sorted(runs, key=lambda r: (r.task, r.variant, r.seed)):
        rows.append({"level": "run", "task": r.task, "variant": r.variant, "label": labels.get(r.variant, r.variant),
                     "seed": r.seed, "n": 1, "episodes": r.episodes, "env_steps": r.env_steps,
                     "avg_return": r.avg_return, "se": "", "final_return": r.final_return,
                     "success_rate": r.success_rate,
                     "steps_to_90": steps_to_success(r.steps, r.successes) if r.successes is not None else "",
                     "success_last_10pct": _late_success(r) if r.successes is not None else "",
                     "g_star": " ".join(r.g_star) if r.g_star is not None else ""})
    for (v, t), c in sorted(cells.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        ref = PAPER.get(table or "", {}).get(labels.get(v, v), {}).get(t)
        rows.append({"level": "aggregate", "task": t, "variant": v, "label": labels.get(v, v), "seed": "",
                     "n": c.n, "avg_return": c.mean, "se": c.se if math.isfinite(c.se) else "",
                     "paper_mean": ref[0] if ref else "", "paper_se": ref[1] if ref else ""})
    paths["csv"] = write_text(out / "results.csv", _csv(rows))

    curve_rows = []
    for t in tasks:
        data = curves(runs, t, variants, bins)
        if not data:
            continue
        seeds = {v: sum(r.task == t and r.variant == v for r in runs) for v in data}
        named = {v: f"{labels.get(v, v)} ({seeds[v]} seed{'s' * (seeds[v] != 1)})" for v in data}
        paths[f"curve_{t}"] = _plot(t, data, named, out / f"curve_{t}.png")
        for v, (x, m, se) in data.items():
            curve_rows += [{"task": t, "variant": v, "env_steps": float(xi), "mean_return": float(mi),
                            "se": float(si) if math.isfinite(si) else ""} for xi, mi, si in zip(x, m, se)]
    paths["curves_csv"] = write_text(out / "curves.csv", _csv(curve_rows))
    return paths
