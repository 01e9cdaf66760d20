"""Tests of the diagnostic pictures: files written, and the MRF/history figures reflect their inputs."""

from __future__ import annotations

import os
import warnings

import matplotlib
import matplotlib.image
import numpy as np
import pytest
from matplotlib.collections import LineCollection, PathCollection
from matplotlib.colors import to_rgba

from hubsgo_ppl.diagnostics.arviz import to_inference_data
from hubsgo_ppl.diagnostics.plots import (
    NEGATIVE_COLOR,
    POSITIVE_COLOR,
    ZERO_COLOR,
    batch_means,
    edge_styles,
    marginals_history_figure,
    mrf_graph_figure,
    node_styles,
    plot_forest,
    plot_marginals_history,
    plot_mrf_graph,
    plot_posterior,
    plot_trace,
)

NAMES = ["yellow_key", "yellow_door", "blue_key"]
EDGES = [("yellow_key", "yellow_door", +1), ("yellow_key", "blue_key", -1)]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def idata():
    rng = np.random.default_rng(0)
    w = (rng.random((4, 200, 3)) < np.array([0.9, 0.6, 0.2])).astype(np.int8)
    return to_inference_data(w, NAMES, log_q=rng.normal(-2.0, 1.0, (4, 200)), edges=EDGES)


def _assert_png(path, min_px=(300, 300)):
    assert path.is_file()
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000
    height, width = matplotlib.image.imread(path).shape[:2]
    assert height >= min_px[0] and width >= min_px[1]
    assert height <= 6000 and width <= 6000
    assert sorted(os.listdir(path.parent)) == [path.name]  # atomic write left no temp file


@pytest.mark.parametrize("plot", [plot_trace, plot_forest, plot_posterior], ids=lambda f: f.__name__)
def test_arviz_plots_write_png_without_warnings(plot, idata, tmp_path):
    path = tmp_path / "out" / f"{plot.__name__}.png"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # ArviZ/matplotlib deprecation noise must be handled
        written = plot(idata, path)
    assert written == path
    _assert_png(path)


def test_arviz_plots_reject_bad_input(idata, tmp_path):
    with pytest.raises(ValueError, match="InferenceData"):
        plot_trace({"w": 1}, tmp_path / "x.png")
    with pytest.raises(ValueError, match=r"\['pairs'\] not in the posterior"):
        plot_posterior(idata, tmp_path / "x.png", var_names=["pairs"])
    assert not list(tmp_path.iterdir())


def test_batch_means_are_per_chain_batch_averages():
    w = np.zeros((2, 10, 1), dtype=np.int8)
    w[0, :, 0] = [1, 1, 1, 0, 1, 0, 0, 0, 0, 1]  # first draw dropped: 10 draws -> 3 batches of 3
    w[1, :, 0] = 1
    out = batch_means(to_inference_data(w, ["g"]), n_batches=3).posterior["w"]
    assert out.dims == ("chain", "draw", "subgoal") and out.coords["subgoal"].values.tolist() == ["g"]
    np.testing.assert_allclose(out.values[..., 0], [[2 / 3, 1 / 3, 1 / 3], [1, 1, 1]])
    with pytest.raises(ValueError, match="n_batches"):
        batch_means(to_inference_data(w, ["g"]), n_batches=1)


def test_node_styles_map_marginals_to_area_and_colour():
    p = np.array([0.0, 0.25, 1.0])
    sizes, colors = node_styles(p, min_size=100.0, max_size=500.0)
    np.testing.assert_allclose(sizes, [100.0, 200.0, 500.0])
    cmap = matplotlib.colormaps["viridis"]
    np.testing.assert_allclose(colors, [cmap(0.0), cmap(0.25), cmap(1.0)])
    for bad in ([0.2, 1.5], [np.nan], [[0.5]]):
        with pytest.raises(ValueError, match="marginals"):
            node_styles(bad)


def test_edge_styles_width_proportional_to_abs_coupling_and_colour_by_sign():
    widths, colors = edge_styles([2.0, -1.0, 0.5, 0.0], max_width=8.0, min_width=0.5)
    np.testing.assert_allclose(widths, [8.0, 4.0, 2.0, 0.5])  # |J| / max|J| * 8, floor 0.5
    assert colors == [POSITIVE_COLOR, NEGATIVE_COLOR, POSITIVE_COLOR, ZERO_COLOR]
    widths, _ = edge_styles([-3.0, 3.0])
    assert widths[0] == widths[1]  # width depends on |J| only
    with pytest.raises(ValueError, match="finite"):
        edge_styles([1.0, np.inf])


def test_mrf_graph_figure_reflects_inputs():
    marginals = np.array([0.9, 0.5, 0.1])
    couplings = {("yellow_door", "yellow_key"): 1.5, ("yellow_key", "blue_key"): -0.75}  # either orientation
    fig = mrf_graph_figure(NAMES, marginals, EDGES, couplings)
    ax = fig.axes[0]
    nodes = [c for c in ax.collections if isinstance(c, PathCollection)]
    edges = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert len(nodes) == 1 and len(edges) == 1
    exp_sizes, exp_colors = node_styles(marginals)
    np.testing.assert_allclose(nodes[0].get_sizes(), exp_sizes)
    np.testing.assert_allclose(nodes[0].get_facecolors(), exp_colors)
    exp_widths, exp_edge_colors = edge_styles([1.5, -0.75])
    np.testing.assert_allclose(edges[0].get_linewidths(), exp_widths)
    np.testing.assert_allclose(edges[0].get_colors(), [to_rgba(c) for c in exp_edge_colors])
    texts = {t.get_text() for t in ax.texts}
    assert {"yellow_key\nP=0.90", "blue_key\nP=0.10", "+1.50", "-0.75"} <= texts
    assert len(fig.axes) == 2 and fig.axes[1].get_ylabel() == "P(w_i = 1)"  # the colourbar


def test_plot_mrf_graph_writes_png_and_validates(tmp_path):
    path = plot_mrf_graph(NAMES, [0.9, 0.5, 0.1], EDGES, np.array([1.0, -2.0]), tmp_path / "mrf.png")
    _assert_png(path)
    with pytest.raises(ValueError, match=r"one J per edge: expected shape \(2,\)"):
        mrf_graph_figure(NAMES, [0.9, 0.5, 0.1], EDGES, [1.0])
    with pytest.raises(ValueError, match="no value for edge"):
        mrf_graph_figure(NAMES, [0.9, 0.5, 0.1], EDGES, {("yellow_key", "yellow_door"): 1.0})
    with pytest.raises(ValueError, match="names has 3 entries"):
        mrf_graph_figure(NAMES, [0.9, 0.5], EDGES, [1.0, -1.0])
    with pytest.raises(ValueError, match=r"unknown sub-goal\(s\) \['red_key'\]"):
        mrf_graph_figure(NAMES, [0.9, 0.5, 0.1], [("red_key", "blue_key")], [1.0])


def test_marginals_history_figure_plots_each_subgoal_over_steps(tmp_path):
    steps = np.array([0, 100, 250, 400])
    m = np.array([[0.5, 0.5, 0.5], [0.6, 0.4, 0.5], [0.8, 0.3, 0.5], [0.9, 0.1, 0.5]])
    ax = marginals_history_figure(steps, m, NAMES).axes[0]
    lines = ax.get_lines()
    assert [ln.get_label() for ln in lines] == NAMES
    for i, ln in enumerate(lines):
        np.testing.assert_array_equal(ln.get_xdata(), steps)
        np.testing.assert_array_equal(ln.get_ydata(), m[:, i])
    _assert_png(plot_marginals_history(steps, m, NAMES, tmp_path / "history.png"))


@pytest.mark.parametrize(
    "steps, marginals, match",
    [
        (np.array([0, 100, 100]), np.full((3, 3), 0.5), "strictly increasing"),
        (np.array([0, 100]), np.full((3, 3), 0.5), r"shape \(T, N\) with T = len\(steps\) = 2"),
        (np.array([0, 100]), np.full((2, 3), 1.2), r"probabilities in \[0, 1\]"),
        (np.array([0, 100]), np.full((2, 2), 0.5), "names has 3 entries"),
    ],
)
def test_marginals_history_rejects_bad_input(steps, marginals, match):
    with pytest.raises(ValueError, match=match):
        marginals_history_figure(steps, marginals, NAMES)


@pytest.mark.parametrize("model", ["keydoor-specific", "keydoor_n17-specific", "stack_cubes-fully_connected"])
def test_coupling_labels_overlap_no_label_and_no_node_on_a_shipped_spec(model):
    """Each coupling of a shipped spec is labelled on the graph, where its label overlaps no other label
    (coupling or node name) and no node."""
    import itertools

    from hubsgo_ppl.diagnostics.mrf_figure import coupling_labels
    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.specs import load_model_spec

    spec = load_model_spec(model)
    graph = SubgoalGraph(spec.subgoals, [(u, v, 0) for u, v, _ in spec.edges]).preset(spec.graph)
    rng = np.random.default_rng(0)
    marginals = rng.uniform(0.0, 1.0, len(spec.subgoals))
    couplings = rng.uniform(-4.0, 4.0, graph.num_edges)
    fig = mrf_graph_figure(spec.subgoals, marginals, graph.edges, couplings)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    labels = coupling_labels(fig)
    assert sorted(t.get_text() for t in labels) == sorted(f"{x:+.2f}" for x in couplings)
    boxes = [t.get_window_extent(renderer) for t in labels]
    assert not [(a, b) for a, b in itertools.combinations(boxes, 2) if a.overlaps(b)]
    ax = fig.axes[0]
    names = [t.get_window_extent(renderer) for t in ax.texts if t not in labels]
    assert len(names) == len(spec.subgoals)
    assert not [(a, b) for a in boxes for b in names if a.overlaps(b)]
    nodes = next(c for c in ax.collections if isinstance(c, PathCollection))
    centres = ax.transData.transform(nodes.get_offsets())
    radii = np.sqrt(nodes.get_sizes()) / 2 * fig.dpi / 72
    for box in boxes:
        nearest = np.clip(centres, [box.x0, box.y0], [box.x1, box.y1])
        assert (np.hypot(*(nearest - centres).T) >= radii).all()
