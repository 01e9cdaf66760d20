"""marginals.png shows the training critic's marginals and those of the critic G* is read from."""

import numpy as np

from hubsgo_ppl.diagnostics.plots import plot_marginals_history


def test_the_end_marginals_are_drawn_as_stars_with_a_legend(tmp_path, monkeypatch):
    import hubsgo_ppl.diagnostics.plots as plots

    seen = {}
    real_save = plots._save

    def save(fig, path):
        seen["fig"] = fig
        return real_save(fig, path)

    monkeypatch.setattr(plots, "_save", save)
    steps, m = np.array([0, 100, 200]), np.array([[0.5, 0.2], [0.7, 0.2], [0.83, 0.1]])
    path = plot_marginals_history(steps, m, ["a", "b"], tmp_path / "m.png", end=[0.91, 0.05], end_step=210)
    assert path.is_file()
    ax = seen["fig"].axes[0]
    stars = [ln for ln in ax.get_lines() if ln.get_marker() == "*"]
    assert [(ln.get_xdata()[0], ln.get_ydata()[0]) for ln in stars] == [(210, 0.91), (210, 0.05)]
    assert [t.get_text() for t in ax.get_legend().get_texts()] == ["a", "b", "settled refit (G*)"]
