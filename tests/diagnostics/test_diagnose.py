"""``hubsgo diagnose``: the files it writes from a trained HUBS-GO run, its summary against the critic's
exact marginals, and its errors."""

import numpy as np
import pandas as pd
import pytest

from hubsgo_ppl.diagnostics.diagnose import diagnose
from hubsgo_ppl.experiments.run import RunConfig, RunError, load_run, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    for agent in ("hubsgo", "hdqn"):
        train(RunConfig(task="keydoor", agent=agent, steps=300, seed=1, overrides=TINY), root / agent, progress=False)
    return root


def test_diagnose_writes_every_file_and_its_means_are_the_critics_marginals(runs, tmp_path):
    result = diagnose(runs / "hubsgo", chains=3, draws=400, burn_in=16, out=tmp_path / "diag")
    paths = result["paths"]
    assert set(paths) == {"summary", "trace", "forest", "posterior", "mrf_graph", "marginals", "netcdf"}
    for key in ("trace", "forest", "posterior", "mrf_graph", "marginals"):
        assert paths[key].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", key
    assert all(p.parent == tmp_path / "diag" for p in paths.values())
    _, env, agent, _ = load_run(runs / "hubsgo")
    env.close()
    critic = agent.filter.critic
    table = result["summary"]
    rows = [f"w[{n}]" for n in critic.names]
    assert set(rows) <= set(table.index) and (result["chains"], result["draws"]) == (3, 400)
    exact = critic.marginals().numpy()                      # keydoor: exact enumeration of q
    mean, sd, ess = (table.loc[rows, c].to_numpy(float) for c in ("mean", "sd", "ess_bulk"))
    se = np.where(ess > 0, sd / np.sqrt(np.maximum(ess, 1.0)), 0.0)
    assert (np.abs(mean - exact) <= 5 * se + 1e-3).all(), (mean, exact, se)
    on_disk = pd.read_csv(paths["summary"], index_col=0)
    np.testing.assert_allclose(on_disk.loc[rows, "mean"].to_numpy(float), mean)


def test_diagnose_errors(runs):
    with pytest.raises(RunError, match="--chains must be at least 2"):
        diagnose(runs / "hubsgo", chains=1)
    with pytest.raises(RunError, match="agent 'hdqn' has no sub-goal critic to diagnose"):
        diagnose(runs / "hdqn", chains=2, draws=10)
