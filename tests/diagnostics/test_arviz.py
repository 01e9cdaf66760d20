"""Tests of the ArviZ conversion, summary and netCDF IO against exact, enumerated answers."""

from __future__ import annotations

import itertools
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest
import torch

from hubsgo_ppl.diagnostics.arviz import (
    SUMMARY_COLUMNS,
    az,
    load_netcdf,
    save_netcdf,
    summary,
    to_inference_data,
)

NAMES = ["yellow_key", "yellow_door", "blue_key", "blue_door"]
EDGES = [("yellow_key", "yellow_door", +1), ("yellow_key", "blue_key", -1), ("blue_key", "blue_door", +1)]


def exact_mrf(rng: np.random.Generator, n: int = 4, shift: float = 0.0, coupling_sd: float = 1.5):
    """A random pairwise MRF (Eq. 1) over n binary indicators, fully enumerated.

    Returns (states (2^n, n) int8, probabilities (2^n,), edges as index pairs).
    """
    theta = rng.normal(0.0, 1.0, n) + shift
    pairs = list(itertools.combinations(range(n), 2))
    coupling = rng.normal(0.0, coupling_sd, len(pairs))
    states = np.array(list(itertools.product((0, 1), repeat=n)), dtype=np.int8)
    energy = states @ theta + sum(j * states[:, u] * states[:, v] for (u, v), j in zip(pairs, coupling))
    p = np.exp(energy - energy.max())
    return states, p / p.sum(), pairs


def iid_chains(rng, states, probs, chains, draws):
    idx = rng.choice(len(probs), size=(chains, draws), p=probs)
    return states[idx], np.log(probs[idx])


# ---------------------------------------------------------------- conversion


@pytest.mark.parametrize(
    "make",
    [
        lambda w: w,
        lambda w: w.astype(bool),
        lambda w: w.astype(np.float32),
        lambda w: torch.from_numpy(w.astype(np.float32)).requires_grad_(True),
        lambda w: torch.from_numpy(w).bool(),
    ],
    ids=["int8", "bool", "float32", "torch-float-grad", "torch-bool"],
)
def test_conversion_dims_coords_and_values(make):
    rng = np.random.default_rng(0)
    w = rng.integers(0, 2, size=(3, 7, 4)).astype(np.int8)
    idata = to_inference_data(make(w), NAMES)
    da = idata.posterior["w"]
    assert da.dims == ("chain", "draw", "subgoal")
    assert da.shape == (3, 7, 4)
    assert da.coords["subgoal"].values.tolist() == NAMES
    assert da.dtype == np.int8  # ArviZ's summary fails on bool
    np.testing.assert_array_equal(da.values, w)
    assert set(idata.posterior.data_vars) == {"w"}


def test_conversion_log_q_and_pair_statistics():
    rng = np.random.default_rng(1)
    w = rng.integers(0, 2, size=(2, 50, 4))
    log_q = torch.from_numpy(rng.normal(size=(2, 50)))
    idata = to_inference_data(w, NAMES, log_q=log_q, edges=EDGES)
    post = idata.posterior
    assert post["log_q"].dims == ("chain", "draw")
    np.testing.assert_array_equal(post["log_q"].values, log_q.numpy())
    assert post["pair"].dims == ("chain", "draw", "edge")
    assert post["edge"].values.tolist() == ["yellow_key--yellow_door", "yellow_key--blue_key", "blue_key--blue_door"]
    for k, (u, v, _) in enumerate(EDGES):
        expected = w[..., NAMES.index(u)] * w[..., NAMES.index(v)]
        np.testing.assert_array_equal(post["pair"].values[..., k], expected)


def test_conversion_unsigned_edges_and_empty_edge_list():
    w = np.ones((1, 3, 4), dtype=np.int8)
    idata = to_inference_data(w, NAMES, edges=[("blue_door", "yellow_key")])
    assert idata.posterior["edge"].values.tolist() == ["blue_door--yellow_key"]
    # The "independent" preset has E = {} (Sec. 3.3): no pair variable rather than a 0-length one.
    assert "pair" not in to_inference_data(w, NAMES, edges=[]).posterior


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"samples": np.zeros((5, 4))}, r"\(chains, draws, N\).*samples\[None\]"),
        ({"samples": np.zeros((1, 5, 4, 1))}, r"\(chains, draws, N\)"),
        ({"samples": np.zeros((1, 5, 3))}, r"names has 4 entries but samples have N=3"),
        ({"samples": np.full((1, 5, 4), 0.5)}, r"binary indicators.*0\.5"),
        ({"samples": np.full((1, 5, 4), 2)}, r"binary indicators"),
        ({"names": ["a", "a", "b", "c"]}, r"unique.*'a'"),
        ({"names": "abcd"}, r"single string"),
        ({"log_q": np.zeros((1, 4))}, r"log_q must have shape \(chains, draws\) = \(1, 5\)"),
        ({"log_q": np.array([[0, 0, -np.inf, 0, 0]])}, r"log_q must be finite"),
        ({"edges": [("yellow_key", "red_door")]}, r"unknown sub-goal\(s\) \['red_door'\]"),
        ({"edges": [("blue_key", "blue_key")]}, r"self-loop"),
        ({"edges": [("blue_key", "blue_door"), ("blue_door", "blue_key")]}, r"repeats"),
        ({"edges": ["blue_key--blue_door"]}, r"\(u, v\) or \(u, v, sign\)"),
    ],
)
def test_conversion_rejects_bad_input(kwargs, match):
    args = {"samples": np.zeros((1, 5, 4)), "names": NAMES} | kwargs
    with pytest.raises(ValueError, match=match):
        to_inference_data(**args)


# ---------------------------------------------------------------- summary vs exact answers


def test_summary_iid_chains_from_exact_mrf_match_enumeration():
    rng = np.random.default_rng(2024)
    states, probs, pairs = exact_mrf(rng)
    chains, draws = 4, 2000
    w, log_q = iid_chains(rng, states, probs, chains, draws)
    edges = [(NAMES[u], NAMES[v]) for u, v in pairs]
    idata = to_inference_data(w, NAMES, log_q=log_q, edges=edges)
    table = summary(idata, ("w", "pair", "log_q"))
    assert tuple(table.columns) == SUMMARY_COLUMNS
    n = chains * draws

    exact_w = probs @ states
    exact_pair = np.array([probs @ (states[:, u] * states[:, v]) for u, v in pairs])
    exact = np.concatenate([exact_w, exact_pair])
    # i.i.d. draws: the Monte Carlo sd of each mean is sqrt(p(1-p)/n); allow 4.5 of them.
    tol = 4.5 * np.sqrt(exact * (1 - exact) / n)
    got = table["mean"].to_numpy()[:-1]
    assert np.all(np.abs(got - exact) <= tol), (got, exact, tol)
    # Same for log q: its mean is -H(q), its variance Var[log q].
    entropy = -(probs @ np.log(probs))
    var_lq = probs @ np.log(probs) ** 2 - entropy**2
    assert abs(table.loc["log_q", "mean"] + entropy) <= 4.5 * np.sqrt(var_lq / n)
    # Independent chains from the target distribution: converged and (nearly) independent draws.
    assert (table["r_hat"] <= 1.01).all(), table["r_hat"]
    assert table["ess_bulk"].between(0.7 * n, 1.25 * n).all(), table["ess_bulk"]
    assert table["ess_tail"].between(0.6 * n, 1.25 * n).all(), table["ess_tail"]
    np.testing.assert_allclose(table["sd"].to_numpy()[:4], np.sqrt(exact_w * (1 - exact_w)), atol=0.02)
    assert not table["constant"].any()
    assert table.index[:4].tolist() == [f"w[{x}]" for x in NAMES]


def test_summary_flags_chains_stuck_at_different_values():
    # Each chain constant at a different joint state: zero within-chain variance.
    stuck = np.array([[0, 0, 1, 1], [0, 1, 0, 1], [1, 0, 1, 0], [1, 1, 0, 0]], dtype=np.int8)
    w = np.repeat(stuck[:, None, :], 500, axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # ArviZ's divide-by-zero noise must stay inside summary()
        table = summary(to_inference_data(w, NAMES))
    # W = 0 < B: R-hat's limit is +inf (ArviZ alone would say NaN, which passes "r_hat <= 1.01").
    assert np.isposinf(table["r_hat"]).all(), table["r_hat"]
    assert not table["constant"].any()
    # One chain stuck at 1 while the others mix around P = 0.3.
    rng = np.random.default_rng(4)
    w = (rng.random((4, 1000, 4)) < 0.3).astype(np.int8)
    w[0] = 1
    table = summary(to_inference_data(w, NAMES))
    assert np.isfinite(table["r_hat"]).all() and (table["r_hat"] > 1.1).all(), table["r_hat"]


def test_summary_flags_chains_from_different_distributions():
    rng = np.random.default_rng(7)
    # Same J, unaries shifted down for half the chains and up for the other half.
    states, probs_a, _ = exact_mrf(np.random.default_rng(11), shift=-2.0, coupling_sd=0.5)
    _, probs_b, _ = exact_mrf(np.random.default_rng(11), shift=2.0, coupling_sd=0.5)
    wa, _ = iid_chains(rng, states, probs_a, 2, 1000)
    wb, _ = iid_chains(rng, states, probs_b, 2, 1000)
    table = summary(to_inference_data(np.concatenate([wa, wb]), NAMES))
    gap = np.abs(probs_a @ states - probs_b @ states)
    assert (gap > 0.5).all(), gap  # the test's premise: every marginal differs between the two halves
    assert (table["r_hat"] > 1.1).all(), table["r_hat"]


@pytest.mark.parametrize("flip", [0.1, 0.25])
def test_summary_ess_of_sticky_markov_chain_matches_theory(flip):
    # Symmetric two-state chain flipping with probability f: lag-k autocorrelation (1-2f)^k, so
    # the integrated autocorrelation time is (1-f)/f and ESS = n f / (1-f).
    rng = np.random.default_rng(3)
    chains, draws = 4, 2000
    start = rng.integers(0, 2, size=(chains, 1))
    x = (start + np.cumsum(rng.random((chains, draws)) < flip, axis=1)) % 2
    w = np.stack([x, rng.integers(0, 2, size=(chains, draws))], axis=-1)
    table = summary(to_inference_data(w, ["sticky", "iid"]))
    expected = chains * draws * flip / (1 - flip)
    assert 0.75 * expected <= table.loc["w[sticky]", "ess_bulk"] <= 1.3 * expected
    assert table.loc["w[iid]", "ess_bulk"] > 0.8 * chains * draws > 2 * expected
    assert table.loc["w[sticky]", "r_hat"] < 1.05


def test_summary_constant_subgoal_reports_constant_without_warnings():
    w = np.ones((4, 300, 2), dtype=np.int8)
    w[..., 1] = np.random.default_rng(0).integers(0, 2, size=(4, 300))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        table = summary(to_inference_data(w, ["certain", "coin"]))
    assert table["constant"].tolist() == [True, False]
    assert np.isnan(table.loc["w[certain]", "r_hat"])
    assert table.loc["w[certain]", "mean"] == 1.0


def test_summary_rejects_unknown_variable():
    idata = to_inference_data(np.zeros((2, 5, 4)), NAMES)
    with pytest.raises(ValueError, match=r"\['log_q'\] not in the posterior; available variables: \['w'\]"):
        summary(idata, ("w", "log_q"))
    with pytest.raises(ValueError, match="InferenceData"):
        summary({"w": np.zeros((2, 5, 4))})


# ---------------------------------------------------------------- netCDF


def _idata():
    rng = np.random.default_rng(5)
    return to_inference_data(
        rng.integers(0, 2, size=(2, 30, 4)), NAMES, log_q=rng.normal(size=(2, 30)), edges=EDGES
    )


def test_netcdf_round_trip_preserves_values_and_coords(tmp_path):
    idata = _idata()
    path = save_netcdf(idata, tmp_path / "run" / "posterior.nc")
    assert path == tmp_path / "run" / "posterior.nc" and path.stat().st_size > 0
    back = load_netcdf(path)
    for var in ("w", "log_q", "pair"):
        np.testing.assert_array_equal(back.posterior[var].values, idata.posterior[var].values)
        assert back.posterior[var].dims == idata.posterior[var].dims
    assert back.posterior["subgoal"].values.tolist() == NAMES
    assert back.posterior["edge"].values.tolist() == idata.posterior["edge"].values.tolist()
    assert back.posterior["w"].dtype == np.int8
    assert sorted(p.name for p in path.parent.iterdir()) == ["posterior.nc"]


def test_netcdf_write_is_atomic(tmp_path, monkeypatch):
    path = tmp_path / "posterior.nc"
    save_netcdf(_idata(), path)
    before = path.read_bytes()

    def broken_write(self, filename, *args, **kwargs):
        with open(filename, "wb") as fh:
            fh.write(b"CDF\x01 partial")
        raise OSError("disk full")

    monkeypatch.setattr(az.InferenceData, "to_netcdf", broken_write)
    with pytest.raises(OSError, match="disk full"):
        save_netcdf(_idata(), path)
    assert path.read_bytes() == before  # the old posterior survives
    with pytest.raises(OSError, match="disk full"):
        save_netcdf(_idata(), tmp_path / "fresh.nc")
    assert sorted(os.listdir(tmp_path)) == ["posterior.nc"]  # no partial or temp files


def test_netcdf_errors_are_clear(tmp_path):
    with pytest.raises(FileNotFoundError, match="save_netcdf"):
        load_netcdf(tmp_path / "missing.nc")
    with pytest.raises(ValueError, match="InferenceData"):
        save_netcdf({"w": 1}, tmp_path / "x.nc")


def _run_with_fresh_cache(code: str, cache) -> str:
    """Run ``code`` in a new interpreter whose user cache folder is ``cache`` (no ArviZ stamp yet, so the
    import writes one); returns its stdout, after checking that it exited cleanly."""
    env = dict(os.environ, XDG_CACHE_HOME=str(cache), MPLBACKEND="Agg")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_import_hides_only_arvizs_refactor_notice(tmp_path):
    # ArviZ 0.23 warns once per day (stamp in the user cache dir); a fresh cache makes it fire.
    code = (
        "import warnings; warnings.simplefilter('error', FutureWarning)\n"
        "import hubsgo_ppl.diagnostics.arviz\n"
        "try:\n"
        "    warnings.warn('a real one', FutureWarning)\n"
        "except FutureWarning:\n"
        "    print('still-raised')\n"
    )
    assert _run_with_fresh_cache(code, tmp_path).strip() == "still-raised"
    assert (tmp_path / "arviz" / "daily_warning").is_file()  # the notice really was triggered


def test_import_survives_another_process_renaming_the_daily_stamp_first(tmp_path):
    # Two processes importing ArviZ 0.23 for the first time on a day write the stamp through the same
    # temporary name; the loser's rename finds it gone. Simulated here: that rename fails once.
    code = (
        "import pathlib\n"
        "real = pathlib.Path.replace\n"
        "failed = []\n"
        "def raced(self, target):\n"
        "    if self.name == 'daily_warning.tmp' and not failed:\n"
        "        failed.append(self)\n"
        "        self.unlink()\n"
        "        raise FileNotFoundError(2, 'No such file or directory', str(self))\n"
        "    return real(self, target)\n"
        "pathlib.Path.replace = raced\n"
        "from hubsgo_ppl.diagnostics.arviz import az\n"
        "print(len(failed), az.__version__.split('.')[0])\n"
    )
    # the race happened, and the import still succeeded
    assert _run_with_fresh_cache(code, tmp_path).split() == ["1", "0"]
    assert (tmp_path / "arviz" / "daily_warning").is_file()
