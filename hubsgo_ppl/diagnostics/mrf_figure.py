"""The picture of the learned pairwise MRF of Eq. 1, built (not saved) on a fresh Figure.

Nodes on a circle in the sub-goal order, sized and coloured by P(w_i = 1) with a colourbar; edges of
width proportional to |J_uv|, coloured by sign (positive blue, negative orange, as in the paper's
Fig. 4); each node labelled with its name and marginal, each edge with its coupling J.

Each coupling label is placed where it covers no other label and no node: along its edge first
(the middle, then towards either end), then beside it towards the circle's centre, tied to its edge by
a thin line of the edge's colour. A label with no free place is not drawn on the graph; the
couplings left out are listed under it. :func:`coupling_labels` returns the labels drawn, so that
their layout can be checked. :func:`hubsgo_ppl.diagnostics.plots.plot_mrf_graph` writes the PNG.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib
import networkx as nx
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from .arviz import _check_edges, _check_names, _to_numpy

__all__ = ["POSITIVE_COLOR", "NEGATIVE_COLOR", "ZERO_COLOR", "NODE_CMAP", "COUPLING_GID", "node_styles",
           "edge_styles", "coupling_labels", "mrf_graph_figure"]

#: Edge colours by sign of the coupling J (the paper's Fig. 4: positive blue, negative orange).
POSITIVE_COLOR = "tab:blue"
NEGATIVE_COLOR = "tab:orange"
ZERO_COLOR = "0.6"
#: Colour map of node marginals; fixed to [0, 1] so pictures of different runs compare.
NODE_CMAP = "viridis"
#: the ``gid`` of every coupling label drawn on the graph (:func:`coupling_labels`)
COUPLING_GID = "coupling"
DPI = 110
#: where along an edge a label may sit (fractions of the edge from u), in the order tried
_ALONG = (0.5, 0.38, 0.62, 0.26, 0.74, 0.14, 0.86)
#: how far beside its edge, towards the centre (in label heights), in the order tried
_BESIDE = (0.0, 1.2, 2.4, 3.6, 4.8)
_GAP_PX = 2.0           # the least room kept between two labels, and between a label and a node


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


def coupling_labels(fig: Figure) -> list[Text]:
    """The coupling labels drawn on the graph of an :func:`mrf_graph_figure` (those left out are listed
    under it instead)."""
    return [t for t in fig.axes[0].texts if t.get_gid() == COUPLING_GID]


def _hits_disc(box: Bbox, centre: np.ndarray, radius: float) -> bool:
    nearest = np.clip(centre, [box.x0, box.y0], [box.x1, box.y1])
    return float(np.hypot(*(nearest - centre))) < radius


def _place_coupling_labels(fig: Figure, ax: Any, pos: Mapping[str, np.ndarray], pairs: list[tuple[str, str]],
                           j: np.ndarray, colors: list[str], sizes: np.ndarray, names: list[str]) -> list[int]:
    """Draw each coupling label where it overlaps no other label and no node (see the module docstring);
    strongest couplings first. Returns the indices of the edges whose label found no place."""
    FigureCanvasAgg(fig)
    fig.draw_without_rendering()            # the layout is final: data -> pixels no longer moves
    renderer = fig.canvas.get_renderer()
    to_px, to_data = ax.transData, ax.transData.inverted()
    taken = [t.get_window_extent(renderer).expanded(1.0, 1.0) for t in ax.texts]      # the node labels
    discs = [(to_px.transform(pos[n]), np.sqrt(s) / 2 * fig.dpi / 72 + _GAP_PX) for n, s in zip(names, sizes)]
    centre = to_px.transform((0.0, 0.0))
    left_out = []
    for k in sorted(range(len(pairs)), key=lambda k: (-abs(j[k]), k)):
        u, v = pairs[k]
        text = ax.text(0.0, 0.0, f"{j[k]:+.2f}", fontsize=8, ha="center", va="center", gid=COUPLING_GID,
                       zorder=5, bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": colors[k], "lw": 0.8})
        text.set_in_layout(False)
        box = text.get_window_extent(renderer)
        w, h = box.width + 2 * _GAP_PX, box.height + 2 * _GAP_PX
        p0, p1 = to_px.transform(pos[u]), to_px.transform(pos[v])
        normal = np.array([p0[1] - p1[1], p1[0] - p0[0]])
        normal = normal / (np.hypot(*normal) or 1.0)
        if np.dot(normal, centre - (p0 + p1) / 2) < 0:
            normal = -normal                # beside the edge means towards the circle's centre
        spot = None
        for beside in _BESIDE:
            for t in _ALONG:
                on_edge = p0 + t * (p1 - p0)
                at = on_edge + beside * h * normal
                cand = Bbox.from_bounds(at[0] - w / 2, at[1] - h / 2, w, h)
                if not any(cand.overlaps(b) for b in taken) and not any(_hits_disc(cand, c, r) for c, r in discs):
                    spot = (at, on_edge, beside, cand)
                    break
            if spot is not None:
                break
        if spot is None:
            text.remove()
            left_out.append(k)
            continue
        at, on_edge, beside, cand = spot
        text.set_position(to_data.transform(at))
        taken.append(cand)
        if beside:
            ends = to_data.transform(np.stack([on_edge, at]))
            line = ax.plot(ends[:, 0], ends[:, 1], color=colors[k], lw=0.7, zorder=4)[0]
            line.set_in_layout(False)
    return sorted(left_out)


def mrf_graph_figure(
    names: Sequence[str],
    marginals: Any,
    edges: Sequence[Sequence[Any]],
    couplings: Any,
    title: str | None = None,
) -> Figure:
    """Build (without saving) the picture of the learned MRF (the module docstring says what it shows).

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

    fig = Figure(figsize=(8, 7), layout="constrained", dpi=DPI)
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
    left_out = _place_coupling_labels(fig, ax, pos, pairs, j, edge_colors, sizes, list(names))
    if left_out:
        listed = "; ".join(f"{pairs[k][0]} — {pairs[k][1]} {j[k]:+.2f}" for k in left_out)
        fig.text(0.5, 0.005, f"couplings with no room on the graph: {listed}", ha="center", va="bottom",
                 fontsize=7, wrap=True)
    return fig
