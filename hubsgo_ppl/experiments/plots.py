"""Learning-curve pictures (matplotlib, Agg), written atomically."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np

__all__ = ["rolling_mean", "plot_learning_curve", "plot_run_curve", "read_revisions", "REVISIONS_CSV"]

#: one line per revision of the critic spec (experiments/revise.py writes it; the learning curve marks them)
REVISIONS_CSV = "revisions.csv"


def rolling_mean(x: Sequence[float], window: int) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.size == 0:
        return x
    c = np.cumsum(np.insert(x, 0, 0.0))
    out = np.empty_like(x)
    for i in range(x.size):
        lo = max(0, i + 1 - window)
        out[i] = (c[i + 1] - c[lo]) / (i + 1 - lo)
    return out


def plot_learning_curve(steps: Sequence[float], returns: Sequence[float], success: Sequence[float],
                        path: str | Path, title: str = "", window: int = 20,
                        revisions: Sequence[tuple[int, float]] = ()) -> Path:
    """The learning curve as a PNG; ``revisions`` ((number, env step) pairs, from ``hubsgo revise``) are
    marked as dotted lines labelled r1, r2, ..."""
    from matplotlib.figure import Figure   # no pyplot: leaves the caller's backend (e.g. a notebook's) alone

    from .io import atomic_write

    fig = Figure(figsize=(7, 4))
    ax = fig.subplots()
    ax.plot(steps, returns, color="0.8", lw=0.8, label="episode return")
    ax.plot(steps, rolling_mean(returns, window), color="C0", lw=2, label=f"return (mean of {window})")
    ax.plot(steps, rolling_mean(success, window), color="C2", lw=1.5, ls="--", label="success rate")
    for k, (number, step) in enumerate(revisions):
        ax.axvline(step, color="C3", lw=1.2, ls=":", label="spec revised" if k == 0 else None)
        ax.annotate(f"r{number}", (step, 1.0), xytext=(3, -10), textcoords="offset points", color="C3", fontsize=8)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("return / success")
    ax.set_ylim(-0.05, 1.05)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    return Path(path)


def read_revisions(run_dir: str | Path) -> list[dict[str, str]]:
    """The rows of ``RUN/revisions.csv`` (none for a run never revised)."""
    from .logger import read_csv_rows

    return read_csv_rows(Path(run_dir) / REVISIONS_CSV)


def plot_run_curve(run_dir: str | Path, resolved: dict[str, Any] | None = None,
                   path: str | Path | None = None) -> Path | None:
    """``learning_curve.png`` of a run (default ``RUN/learning_curve.png``) from its metrics.csv, with a
    dotted vertical line at the env step of each revision of its critic spec; None without episodes."""
    from .checkpoint import run_config
    from .logger import read_csv_rows

    run_dir = Path(run_dir)
    rows = read_csv_rows(run_dir / "metrics.csv", required=("env_steps", "return", "success"))
    if not rows:
        return None
    if resolved is None:
        resolved = run_config(run_dir)
    path = Path(path) if path is not None else run_dir / "learning_curve.png"
    title = f"{resolved['agent']} on {resolved['task']} (seed {resolved['seed']})"
    steps, rets, succ = ([float(r[k]) for r in rows] for k in ("env_steps", "return", "success"))
    revisions = [(int(r["revision"]), float(r["env_steps"])) for r in read_revisions(run_dir)]
    return plot_learning_curve(steps, rets, succ, path, title=title, revisions=revisions)
