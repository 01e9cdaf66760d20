"""Learning-curve pictures: the trailing rolling mean and an atomically written PNG."""

import numpy as np
import pytest

from hubsgo_ppl.experiments.plots import plot_learning_curve, rolling_mean


def test_rolling_mean_is_the_trailing_window_mean():
    x = [1.0, 2.0, 6.0, 3.0, 0.0]
    np.testing.assert_allclose(rolling_mean(x, 3), [1.0, 1.5, 3.0, 11 / 3, 3.0])
    np.testing.assert_allclose(rolling_mean(x, 1), x)
    np.testing.assert_allclose(rolling_mean(x, 100), np.cumsum(x) / np.arange(1, 6))
    assert rolling_mean([], 5).size == 0


def test_plot_writes_a_png_atomically(tmp_path, monkeypatch):
    path = plot_learning_curve([10, 20, 30], [0.0, 0.5, 1.0], [0, 1, 1], tmp_path / "sub" / "curve.png", title="t")
    assert path == tmp_path / "sub" / "curve.png" and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    before = path.read_bytes()
    from matplotlib.figure import Figure

    def broken(self, *args, **kwargs):
        raise RuntimeError("renderer failed")

    monkeypatch.setattr(Figure, "savefig", broken)
    with pytest.raises(RuntimeError, match="renderer failed"):
        plot_learning_curve([1], [0.0], [0], path)
    assert path.read_bytes() == before and [p.name for p in path.parent.iterdir()] == ["curve.png"]
