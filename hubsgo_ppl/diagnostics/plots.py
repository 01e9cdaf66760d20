"""Pictures of the critic's posterior: ArviZ trace/forest/posterior, the learned MRF, marginals.

Every function renders onto a fresh ``matplotlib.figure.Figure`` (no pyplot state, no global
backend switch: saving goes through the Agg canvas whatever the session's backend is), writes a
PNG atomically (temp file + ``os.replace``) and returns the written path.

- :func:`plot_trace`: ArviZ trace plot, one row per sub-goal indicator w_i (and ``log_q``):
  per-chain histograms on the left, the draws against iteration on the right. Stuck chains show
  as flat lines at different levels.
- :func:`plot_forest`: ArviZ forest plot of per-chain estimates of P(w_i = 1) with R-hat. A forest
  of the raw 0/1 draws would mark the median (0 or 1) and a [0, 1] interval, which says nothing,
  so each chain is cut into consecutive batches and the forest shows the batch means: the marker
  is that chain's P(w_i = 1), the bar its Monte Carlo spread, and disagreeing chains stand apart.
- :func:`plot_posterior`: ArviZ posterior plot per indicator (bars at 0 and 1 with the mean,
  i.e. the marginal P(w_i = 1) of Eq. 1, written on it) and of ``log_q`` with its HDI.
- :func:`plot_mrf_graph`: the learned pairwise MRF of Eq. 1 (networkx): nodes sized and coloured
  by P(w_i = 1) with a colourbar, edges of width proportional to |J_uv| coloured by sign (positive
  blue, negative orange, as in the paper's Fig. 4), nodes labelled with name and marginal, edges with
  their coupling where the label overlaps nothing (:mod:`hubsgo_ppl.diagnostics.mrf_figure`).
- :func:`plot_marginals_history`: P(w_i = 1) against training step, one line per sub-goal.

ArviZ 0.23 API (``az.plot_*(..., ax=/axes=)``); see :mod:`hubsgo_ppl.diagnostics.arviz` for what a
port to ArviZ 1.x (``arviz_plots``) changes.
"""

from __future__ import annotations

import contextlib
import math
import os
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from hubsgo_ppl.diagnostics.arviz import _check_names, _to_numpy, atomic_write, az, summary
from hubsgo_ppl.diagnostics.mrf_figure import (DPI, NEGATIVE_COLOR, POSITIVE_COLOR, ZERO_COLOR, edge_styles,
                                               mrf_graph_figure, node_styles)

__all__ = [
    "POSITIVE_COLOR",
    "NEGATIVE_COLOR",
    "ZERO_COLOR",
    "batch_means",
    "node_styles",
    "edge_styles",
    "mrf_graph_figure",
    "marginals_history_figure",
    "plot_trace",
    "plot_forest",
    "plot_posterior",
    "plot_mrf_graph",
    "plot_marginals_history",
]


@contextlib.contextmanager
def _arviz_plot_warnings() -> Iterator[None]:
    # ArviZ 0.23 calls a matplotlib helper the way matplotlib 3.11 deprecates; the warning is about
    # ArviZ's internals, fires once per artist, and says nothing about our data.
    with warnings.catch_warnings():
        warnings.filterwarnings(
            "ignore",
            message="Passing a dict or None as alias_mapping to normalize_kwargs",
            category=matplotlib.MatplotlibDeprecationWarning,
        )
        yield


def _save(fig: Figure, path: str | os.PathLike[str]) -> Path:
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=DPI), suffix=".png")


def _check_idata(idata: Any) -> None:
    if not isinstance(idata, az.InferenceData) or "posterior" not in idata.groups():
        raise ValueError("idata must be an arviz.InferenceData with a posterior group (see to_inference_data)")


def _default_vars(idata: az.InferenceData, var_names: Sequence[str] | None, extra: Sequence[str]) -> list[str]:
    available = list(idata.posterior.data_vars)
    if var_names is None:
        var_names = ["w", *[v for v in extra if v in available]]
    elif isinstance(var_names, str):
        var_names = [var_names]
    missing = [v for v in var_names if v not in available]
    if missing:
        raise ValueError(f"var_names {missing} not in the posterior; available variables: {available}")
    return list(var_names)


def _n_panels(idata: az.InferenceData, var_names: Sequence[str]) -> int:
    total = 0
    for var in var_names:
        da = idata.posterior[var]
        total += math.prod(size for dim, size in da.sizes.items() if dim not in ("chain", "draw"))
    return total


def plot_trace(
    idata: az.InferenceData,
    path: str | os.PathLike[str],
    var_names: Sequence[str] | None = None,
    kind: str = "trace",
) -> Path:
    """ArviZ trace plot of the indicators w (and ``log_q`` if present), one row per sub-goal.

    ``kind="rank_bars"`` swaps the right column for rank plots (uniform bars when chains mix).
    """
    _check_idata(idata)
    var_names = _default_vars(idata, var_names, extra=("log_q",))
    rows = _n_panels(idata, var_names)
    fig = Figure(figsize=(11, 1.7 * rows + 0.6), layout="constrained")
    axes = fig.subplots(rows, 2, squeeze=False)
    with _arviz_plot_warnings():
        az.plot_trace(idata, var_names=var_names, compact=False, kind=kind, axes=axes, show=False)
    return _save(fig, path)


def batch_means(idata: az.InferenceData, var_names: Sequence[str] = ("w",), n_batches: int = 20) -> az.InferenceData:
    """Per-chain batch means: each chain's draws cut into ``n_batches`` consecutive equal batches
    (the remainder at the start is dropped, as burn-in would be), each replaced by its mean.

    Returns an InferenceData with ``draw`` = batch index; for 0/1 indicators each value is a
    batch estimate of P(w_i = 1) under that chain.
    """
    _check_idata(idata)
    var_names = _default_vars(idata, var_names, extra=())
    draws = idata.posterior.sizes["draw"]
    if not isinstance(n_batches, (int, np.integer)) or n_batches < 2:
        raise ValueError(f"n_batches must be an integer >= 2, got {n_batches!r}")
    b = min(int(n_batches), draws)
    if b < 2:
        raise ValueError(f"batch means need at least 2 draws per chain, got {draws}")
    size = draws // b
    start = draws - b * size
    out: dict[str, np.ndarray] = {}
    dims: dict[str, list[str]] = {}
    coords: dict[str, Any] = {}
    for var in var_names:
        da = idata.posterior[var].transpose("chain", "draw", ...)
        vals = da.values[:, start:].astype(np.float64)
        out[var] = vals.reshape(vals.shape[0], b, size, *vals.shape[2:]).mean(axis=2)
        extra_dims = list(da.dims[2:])
        dims[var] = extra_dims
        for d in extra_dims:
            coords[d] = da.coords[d].values.tolist()
    return az.from_dict(posterior=out, dims=dims, coords=coords)


def plot_forest(
    idata: az.InferenceData,
    path: str | os.PathLike[str],
    var_names: Sequence[str] = ("w",),
    n_batches: int = 20,
) -> Path:
    """ArviZ forest plot of per-chain P(w_i = 1) (batch means, see :func:`batch_means`), beside the
    R-hat of the raw draws from :func:`hubsgo_ppl.diagnostics.arviz.summary` (dashed line: 1.01)."""
    batched = batch_means(idata, var_names, n_batches)
    names = list(batched.posterior.data_vars)
    table = summary(idata, names)
    rows = len(table) * batched.posterior.sizes["chain"]
    fig = Figure(figsize=(9, 0.28 * rows + 1.6), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True, gridspec_kw={"width_ratios": [4, 1]})
    with _arviz_plot_warnings():
        # ArviZ's own r_hat column is empty when chains are drawn separately (combined=False).
        az.plot_forest(batched, combined=False, ax=axes[:1], show=False)
    axes[0].set_title(
        f"per-chain P(w=1): median and 94% HDI of {batched.posterior.sizes['draw']} batch means",
        fontsize=10,
    )
    # ArviZ lays variables out top to bottom in summary order, one y tick per variable.
    ticks = sorted(axes[0].get_yticks(), reverse=True)
    if len(ticks) != len(table):
        raise RuntimeError(f"forest plot has {len(ticks)} rows but the summary {len(table)}; ArviZ layout changed")
    r_hat = table["r_hat"].to_numpy(dtype=float)
    finite = np.isfinite(r_hat)
    axes[1].plot(r_hat[finite], np.asarray(ticks)[finite], "o", color="tab:blue", markeredgecolor="k")
    for y, const in zip(ticks, table["constant"]):
        if const:
            axes[1].text(1.0, y, "constant", va="center", ha="left", fontsize=8)
    axes[1].axvline(1.01, color="0.4", ls="--", lw=1)
    hi = max(1.05, float(np.nanmax(r_hat)) * 1.02) if finite.any() else 1.05
    axes[1].set_xlim(0.99, hi)
    axes[1].set_title("r_hat (raw draws)", fontsize=10)
    axes[1].tick_params(left=False)
    return _save(fig, path)


def plot_posterior(
    idata: az.InferenceData,
    path: str | os.PathLike[str],
    var_names: Sequence[str] | None = None,
    ncols: int = 3,
) -> Path:
    """ArviZ posterior plot: each indicator w_i with its mean P(w_i = 1) (no HDI: for a 0/1 variable
    it is just [0, 1]), and ``log_q`` (if present) with its 94% HDI."""
    _check_idata(idata)
    var_names = _default_vars(idata, var_names, extra=("log_q",))
    binary = [v for v in var_names if v in ("w", "pair")]
    other = [v for v in var_names if v not in binary]
    n_bin, n_other = _n_panels(idata, binary), _n_panels(idata, other)
    total = n_bin + n_other
    ncols = max(1, min(ncols, total))
    nrows = math.ceil(total / ncols)
    fig = Figure(figsize=(3.6 * ncols, 2.8 * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    with _arviz_plot_warnings():
        if binary:
            az.plot_posterior(
                idata, var_names=binary, point_estimate="mean", hdi_prob="hide",
                ax=axes[:n_bin], show=False,
            )
        if other:
            az.plot_posterior(
                idata, var_names=other, point_estimate="mean", ax=axes[n_bin:total], show=False
            )
    for ax in axes[total:]:
        ax.set_axis_off()
    return _save(fig, path)


def plot_mrf_graph(
    names: Sequence[str],
    marginals: Any,
    edges: Sequence[Sequence[Any]],
    couplings: Any,
    path: str | os.PathLike[str],
    title: str | None = None,
) -> Path:
    """Draw the learned pairwise MRF q(w; lambda) of Eq. 1 and write it as a PNG.

    Args:
        names: the N sub-goal names.
        marginals: (N,) P(w_i = 1), e.g. ``critic.marginals()``.
        edges: the MRF edges ``(u, v)`` or ``(u, v, sign)`` by name.
        couplings: one J per edge, as an array aligned with ``edges`` or a mapping keyed by
            ``(u, v)`` such as ``critic.factors()["pairwise"]``.
        path: PNG to write.
    """
    return _save(mrf_graph_figure(names, marginals, edges, couplings, title), path)


def marginals_history_figure(steps: Any, marginals: Any, names: Sequence[str]) -> Figure:
    """Build (without saving) the figure of :func:`plot_marginals_history`."""
    t = _to_numpy(steps, "steps")
    m = _to_numpy(marginals, "marginals").astype(np.float64)
    if t.ndim != 1 or t.size < 1:
        raise ValueError(f"steps must be a non-empty 1-D array of training steps, got shape {t.shape}")
    if m.ndim != 2 or m.shape[0] != t.shape[0]:
        raise ValueError(f"marginals must have shape (T, N) with T = len(steps) = {t.shape[0]}, got {m.shape}")
    if t.dtype.kind not in "iuf" or not np.isfinite(t).all():
        raise ValueError("steps must be finite numbers")
    if (np.diff(t) <= 0).any():
        raise ValueError("steps must be strictly increasing; sort the history or drop duplicated checkpoints")
    if not np.isfinite(m).all() or (m < 0).any() or (m > 1).any():
        raise ValueError("marginals must be probabilities in [0, 1]")
    names = _check_names(names, m.shape[1])

    fig = Figure(figsize=(9, 4.8), layout="constrained")
    ax = fig.add_subplot()
    marker = "o" if t.size <= 50 else None
    for i, name in enumerate(names):
        ax.plot(t, m[:, i], marker=marker, markersize=3, label=name)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("training step")
    ax.set_ylabel("P(w_i = 1)")
    ax.set_title("critic marginals over training")
    ax.grid(alpha=0.3)
    ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5), fontsize=8, frameon=False)
    return fig


def plot_marginals_history(
    steps: Any, marginals: Any, names: Sequence[str], path: str | os.PathLike[str],
    end: Any = None, end_step: float | None = None, end_label: str = "settled refit (G*)",
) -> Path:
    """P(w_i = 1) of the critic (Eq. 1) over training and write it as a PNG: ``steps`` (T,)
    strictly increasing, ``marginals`` (T, N), one line per sub-goal, from periodic checkpoints or a
    logged history. ``end`` (N,): the marginals of the critic G* is read from at ``end_step`` (the
    settled refit, whose marginals can differ from the training critic's), drawn as stars in each
    sub-goal's colour with ``end_label`` in the legend."""
    fig = marginals_history_figure(steps, marginals, names)
    if end is not None:
        e = _to_numpy(end, "end").astype(np.float64).reshape(-1)
        if e.shape[0] != len(names) or not np.isfinite(e).all() or (e < 0).any() or (e > 1).any():
            raise ValueError(f"end must be {len(names)} probabilities in [0, 1], one per sub-goal")
        ax = fig.axes[0]
        x = float(end_step) if end_step is not None else float(_to_numpy(steps, "steps")[-1])
        for line, p in zip(ax.get_lines()[: len(names)], e):
            ax.plot([x], [p], marker="*", markersize=11, linestyle="none", color=line.get_color(),
                    markeredgecolor="k", markeredgewidth=0.5)
        handles, labels = ax.get_legend_handles_labels()
        handles = handles[: len(names)] + [Line2D([], [], marker="*", linestyle="none", color="0.4",
                                                  markeredgecolor="k", markersize=11)]
        ax.legend(handles, labels[: len(names)] + [end_label], loc="center left", bbox_to_anchor=(1.0, 0.5),
                  fontsize=8, frameon=False)
        ax.set_title("critic marginals over training (lines) and of the critic G* is read from (stars)")
    return _save(fig, path)
