import pytest
import torch

from hubsgo_ppl.graph import SubgoalGraph, colour_classes


def test_edges_are_normalised_and_indexed():
    g = SubgoalGraph(["a", "b", "c"], [("c", "a", -1), ("b", "c", 0)])
    assert g.n == 3 and g.names == ["a", "b", "c"]
    assert g.edges == [("a", "c", -1), ("b", "c", 0)]
    assert g.edge_index.tolist() == [[0, 2], [1, 2]]
    assert g.edge_sign.tolist() == [-1.0, 0.0]
    assert g.index("c") == 2


def test_presets():
    g = SubgoalGraph(["a", "b", "c", "d"], [("a", "b", 1), ("c", "d", -1)])
    assert g.preset("specific") == g
    assert g.preset("independent").edges == []
    fc = g.preset("fully_connected")
    assert len(fc.edges) == 6
    signs = {(u, v): s for u, v, s in fc.edges}
    assert signs[("a", "b")] == 1 and signs[("c", "d")] == -1 and signs[("a", "c")] == 0
    with pytest.raises(ValueError, match="fully_connected"):
        g.preset("dense")


@pytest.mark.parametrize(
    "names, edges, match",
    [
        ([], [], "N = 0"),
        (["a", "a"], [], "duplicate sub-goal"),
        (["a", "b"], [("a", "x", 1)], "'x' is not a sub-goal; use one of: a, b"),
        (["a", "b"], [("a", "a", 1)], "self-edge"),
        (["a", "b"], [("a", "b", 2)], "sign"),
        (["a", "b"], [("a", "b", 1), ("b", "a", -1)], "duplicate edge"),
    ],
)
def test_bad_graphs_are_rejected(names, edges, match):
    with pytest.raises((ValueError, KeyError), match=match):
        SubgoalGraph(names, edges)


def test_colour_classes_are_independent_sets_covering_all_sites():
    g = SubgoalGraph([str(i) for i in range(7)], [(str(i), str(i + 1), 1) for i in range(6)] + [("0", "6", 1)])
    classes = colour_classes(g.edge_index, g.n)
    assert sorted(torch.cat(classes).tolist()) == list(range(7))
    for idx in classes:
        members = set(idx.tolist())
        for u, v in g.edge_index.tolist():
            assert not (u in members and v in members)
    assert len(classes) == 3  # odd cycle needs three colours
    assert len(colour_classes(g.preset("fully_connected").edge_index, 7)) == 7
    assert len(colour_classes(g.preset("independent").edge_index, 7)) == 1
