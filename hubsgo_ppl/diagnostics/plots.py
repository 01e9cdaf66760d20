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
  blue, negative orange, as in the paper's Fig. 4), nodes labelled with name and marginal.
- :func:`plot_marginals_history`: P(w_i = 1) against training step, one line per sub-goal.

ArviZ 0.23 API (``az.plot_*(..., ax=/axes=)``); see :mod:`hubsgo_ppl.diagnostics.arviz` for what a
port to ArviZ 1.x (``arviz_plots``) changes.
"""

from __future__ import annotations

import contextlib
import math
import os
import warnings
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import networkx as nx
import numpy as np
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from hubsgo_ppl.diagnostics.arviz import _check_edges, _check_names, _to_numpy, atomic_write, az, summary

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

#: Edge colours by sign of the coupling J (the paper's Fig. 4: positive blue, negative orange).
POSITIVE_COLOR = "tab:blue"
NEGATIVE_COLOR = "tab:orange"
ZERO_COLOR = "0.6"
#: Colour map of node marginals; fixed to [0, 1] so pictures of different runs compare.
NODE_CMAP = "viridis"
_DPI = 110


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
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=_DPI), suffix=".png")


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


def node_styles(
    marginals: Any, min_size: float = 300.0, max_size: float = 2400.0, cmap: str = NODE_CMAP
) -> tuple[np.ndarray, np.ndarray]:
    """Node areas (points^2) and RGBA colours for marginals P(w_i = 1).

    Area grows linearly from ``min_size`` at P = 0 to ``max_size`` at P = 1 (so it stays visible at
    0); colour is ``cmap`` on the fixed range [0, 1].
    """
    p = _to_numpy(marginals, "marginals").astype(np.float64)
    if p.ndim != 1:
        raise ValueError(f"marginals must be a 1-D array of P(w_i = 1), got shape {p.shape}")
    if not np.isfinite(p).all() or (p < 0).any() or (p > 1).any():
        raise ValueError(f"marginals must be probabilities in [0, 1], got {p.tolist()}")
    if not 0 <= min_size <= max_size:
        raise ValueError(f"need 0 <= min_size <= max_size, got {min_size}, {max_size}")
    sizes = min_size + (max_size - min_size) * p
    colors = matplotlib.colormaps[cmap](Normalize(0.0, 1.0)(p))
    return sizes, np.asarray(colors)


def edge_styles(couplings: Any, max_width: float = 6.0, min_width: float = 0.6) -> tuple[np.ndarray, list[str]]:
    """Edge widths and colours for couplings J: width proportional to |J| (the largest |J| gets
    ``max_width``; a floor of ``min_width`` keeps weak edges visible) and colour by sign
    (:data:`POSITIVE_COLOR`, :data:`NEGATIVE_COLOR`, :data:`ZERO_COLOR` for J = 0)."""
    j = _to_numpy(couplings, "couplings").astype(np.float64)
    if j.ndim != 1:
        raise ValueError(f"couplings must be a 1-D array with one J per edge, got shape {j.shape}")
    if not np.isfinite(j).all():
        raise ValueError(f"couplings must be finite, got {j.tolist()}")
    if not 0 <= min_width <= max_width:
        raise ValueError(f"need 0 <= min_width <= max_width, got {min_width}, {max_width}")
    scale = np.abs(j).max() if j.size else 0.0
    widths = max_width * np.abs(j) / scale if scale > 0 else np.zeros_like(j)
    widths = np.maximum(widths, min_width)
    colors = [POSITIVE_COLOR if x > 0 else NEGATIVE_COLOR if x < 0 else ZERO_COLOR for x in j]
    return widths, colors


def _coupling_values(couplings: Any, edges: list[tuple[str, str]]) -> np.ndarray:
    if isinstance(couplings, Mapping):
        # critic.factors()["pairwise"] is keyed by (u, v); accept either orientation.
        vals = []
        for u, v in edges:
            if (u, v) in couplings:
                vals.append(couplings[(u, v)])
            elif (v, u) in couplings:
                vals.append(couplings[(v, u)])
            else:
                raise ValueError(f"couplings has no value for edge ({u!r}, {v!r}); keys: {list(couplings)}")
        return np.asarray([float(_to_numpy(x, "coupling")) for x in vals], dtype=np.float64)
    j = _to_numpy(couplings, "couplings").astype(np.float64)
    if j.shape != (len(edges),):
        raise ValueError(f"couplings must hold one J per edge: expected shape ({len(edges)},), got {j.shape}")
    return j


def mrf_graph_figure(
    names: Sequence[str],
    marginals: Any,
    edges: Sequence[Sequence[Any]],
    couplings: Any,
    title: str | None = None,
) -> Figure:
    """Build (without saving) the figure of :func:`plot_mrf_graph`.

    Layout is circular in the given sub-goal order (deterministic, no seed needed).
    """
    p = _to_numpy(marginals, "marginals").astype(np.float64)
    sizes, node_colors = node_styles(p)  # validates shape and range first
    names = _check_names(names, p.shape[0])
    pairs = _check_edges(edges, list(names))
    j = _coupling_values(couplings, pairs)
    widths, edge_colors = edge_styles(j)

    graph = nx.Graph()
    graph.add_nodes_from(names)
    graph.add_edges_from(pairs)
    pos = nx.circular_layout(list(names)) if len(names) > 1 else {names[0]: np.zeros(2)}

    fig = Figure(figsize=(8, 7), layout="constrained")
    ax = fig.add_subplot()
    nx.draw_networkx_edges(
        graph, pos, edgelist=pairs, width=widths.tolist(), edge_color=edge_colors, ax=ax
    )
    nx.draw_networkx_nodes(
        graph, pos, nodelist=list(names), node_size=sizes, node_color=node_colors,
        edgecolors="black", linewidths=0.8, ax=ax,
    )
    # Labels sit just outside the circle so long names do not cover nodes or edges.
    label_pos = {n: np.asarray(xy) * 1.36 for n, xy in pos.items()}
    nx.draw_networkx_labels(
        graph, label_pos, labels={n: f"{n}\nP={pi:.2f}" for n, pi in zip(names, p)},
        font_size=9, ax=ax,
    )
    nx.draw_networkx_edge_labels(
        graph, pos, edge_labels={e: f"{x:+.2f}" for e, x in zip(pairs, j)}, font_size=8, ax=ax
    )
    fig.colorbar(ScalarMappable(Normalize(0.0, 1.0), NODE_CMAP), ax=ax, label="P(w_i = 1)", shrink=0.7)
    ax.legend(
        handles=[
            Line2D([], [], color=POSITIVE_COLOR, lw=3, label="J > 0 (positive)"),
            Line2D([], [], color=NEGATIVE_COLOR, lw=3, label="J < 0 (negative)"),
        ],
        loc="lower left", fontsize=8, frameon=False,
    )
    ax.set_xlim(-1.7, 1.7)
    ax.set_ylim(-1.7, 1.7)
    ax.set_aspect("equal")
    ax.set_axis_off()
    ax.set_title(title or "learned sub-goal MRF: node = P(w_i = 1), edge width = |J|")
    return fig


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
