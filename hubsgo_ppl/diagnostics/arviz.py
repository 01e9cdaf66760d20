"""ArviZ view of the critic's indicator posterior: conversion, per-sub-goal summary, netCDF.

The critic q(w; lambda) of Eq. 1 is a pairwise MRF over indicators w in {0, 1}^N, sampled by
Metropolis-Hastings (Sec. 3.3 and the Appendix; Algorithm 1, line 9). Whether the draws come from
``pyro.infer.MCMC`` with several chains (``get_samples(group_by_chain=True)``) or from the batched
sampler, they arrive here as a plain ``(chains, draws, N)`` 0/1 array, plus optionally ``log q(w)``
per draw and the MRF's edge list. :func:`to_inference_data` turns them into an
``arviz.InferenceData`` whose ``posterior`` group holds:

- ``w``      dims ``(chain, draw, subgoal)``, int8, coords ``subgoal = names``;
- ``log_q``  dims ``(chain, draw)``, float64 (only when ``log_q`` is given);
- ``pair``   dims ``(chain, draw, edge)``, int8, ``w_u * w_v`` per edge, coords
  ``edge = ["u--v", ...]`` (only when a non-empty edge list is given). Its mean is the pairwise
  statistic P(w_u = 1, w_v = 1) whose gradient the pairwise potentials phi of Eq. 1 follow.

ArviZ version
-------------
This module uses the **ArviZ 0.x API** (tested with 0.23.4, the line that still supports numpy < 2,
which robosuite's dependencies pin): ``az.from_dict(posterior=..., dims=..., coords=...)`` building
an ``az.InferenceData``, ``az.summary(..., kind="all", round_to="none")`` returning a
``pandas.DataFrame``, ``InferenceData.to_netcdf`` / ``az.from_netcdf``. ``az.from_pyro`` is not used:
it needs a ``pyro.infer.MCMC`` run with a built-in kernel and fails with the critic's custom MH
kernel, and the batched sampler is not an ``MCMC`` object at all.

A port to ArviZ 1.x (Python >= 3.12, numpy >= 2; split into arviz-base / arviz-stats /
arviz-plots) changes exactly these places: ``from_dict`` there returns an ``xarray.DataTree``
(``from_dict({"posterior": {...}}, dims=..., coords=...)``) instead of ``InferenceData``;
``summary`` moves to ``arviz_stats.summary`` with different column names
(``ess_bulk``/``ess_tail``/``r_hat`` kept, the ``hdi_*`` columns become ``eti``/``hdi`` bounds
named by probability); netCDF IO becomes ``DataTree.to_netcdf`` / ``xarray.open_datatree``; and
the plots in :mod:`hubsgo_ppl.diagnostics.plots` move to ``arviz_plots`` (``plot_trace_dist``,
``plot_forest``, ``plot_dist``) with a different figure/axes model. The module-level
``_AZ_SUMMARY_COLUMNS`` and the three IO/conversion functions are the only touch points.

Importing ArviZ 0.23 emits a once-per-day ``FutureWarning`` announcing that refactor; it is
silenced for our import only (message-matched), so other ``FutureWarning``s still show. That import
also writes a date stamp under the user's cache folder through one fixed temporary name, so two
processes importing ArviZ for the first time on a day (``hubsgo sweep --workers 2``, the measurement
scripts) can race: the second one's rename finds the temporary file gone and the import fails with
``FileNotFoundError``. :func:`_import_arviz` retries the import once, by which time the stamp is there.
"""

from __future__ import annotations

import importlib
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..experiments.io import atomic_path, atomic_write  # noqa: F401 - atomic_write: the package's one writer


def _import_arviz():
    """``import arviz``, without its refactor notice, retried once after the daily stamp's race (module
    docstring)."""
    with warnings.catch_warnings():
        # ArviZ 0.23's import-time notice about the 1.x refactor; see the module docstring.
        warnings.filterwarnings(
            "ignore", message=r"\s*ArviZ is undergoing a major refactor", category=FutureWarning
        )
        try:
            return importlib.import_module("arviz")
        except FileNotFoundError:        # another process renamed the stamp's temporary file first
            sys.modules.pop("arviz", None)
            return importlib.import_module("arviz")


az = _import_arviz()

__all__ = [
    "SUMMARY_COLUMNS",
    "edge_label",
    "to_inference_data",
    "summary",
    "save_netcdf",
    "load_netcdf",
    "atomic_write",
]

#: Columns of :func:`summary`, in order.
SUMMARY_COLUMNS = ("mean", "sd", "ess_bulk", "ess_tail", "r_hat", "constant")
_AZ_SUMMARY_COLUMNS = ["mean", "sd", "ess_bulk", "ess_tail", "r_hat"]


def edge_label(u: str, v: str) -> str:
    """The coordinate label of edge (u, v) in the ``pair`` variable: ``"u--v"``."""
    return f"{u}--{v}"


def _to_numpy(x: Any, what: str) -> np.ndarray:
    # torch tensors (possibly on GPU, possibly requiring grad) without importing torch here.
    if hasattr(x, "detach") and hasattr(x, "cpu"):
        x = x.detach().cpu().numpy()
    try:
        return np.asarray(x)
    except (TypeError, ValueError) as err:
        raise ValueError(f"{what} must be array-like (numpy array or torch tensor): {err}") from err


def _check_names(names: Sequence[str], n: int) -> list[str]:
    if isinstance(names, str):
        raise ValueError(f"names must be a sequence of {n} sub-goal names, got the single string {names!r}")
    names = list(names)
    if len(names) != n:
        raise ValueError(
            f"names has {len(names)} entries but samples have N={n} sub-goals on their last axis; "
            "pass one name per indicator, in the critic's sub-goal order"
        )
    bad = [x for x in names if not isinstance(x, str) or not x]
    if bad:
        raise ValueError(f"sub-goal names must be non-empty strings, got {bad!r}")
    dupes = sorted({x for x in names if names.count(x) > 1})
    if dupes:
        raise ValueError(f"sub-goal names must be unique; repeated: {dupes}")
    return names


def _check_edges(edges: Sequence[Sequence[Any]], names: list[str]) -> list[tuple[str, str]]:
    index = set(names)
    out: list[tuple[str, str]] = []
    seen: set[frozenset[str]] = set()
    for k, edge in enumerate(edges):
        # (u, v) or the graph's signed (u, v, sign): the sign does not change w_u * w_v.
        if isinstance(edge, str) or len(edge) not in (2, 3):
            raise ValueError(
                f"edges[{k}] = {edge!r}: each edge must be (u, v) or (u, v, sign) with sub-goal names u, v"
            )
        u, v = edge[0], edge[1]
        missing = [x for x in (u, v) if x not in index]
        if missing:
            raise ValueError(
                f"edges[{k}] = {edge!r} names unknown sub-goal(s) {missing}; known sub-goals: {names}"
            )
        if u == v:
            raise ValueError(f"edges[{k}] = {edge!r} is a self-loop; an MRF edge joins two different sub-goals")
        key = frozenset((u, v))
        if key in seen:
            raise ValueError(f"edges[{k}] = {edge!r} repeats an earlier edge between {u!r} and {v!r}")
        seen.add(key)
        out.append((u, v))
    return out


def to_inference_data(
    samples: Any,
    names: Sequence[str],
    log_q: Any | None = None,
    edges: Sequence[Sequence[Any]] | None = None,
) -> az.InferenceData:
    """Convert indicator draws w ~ q(w; lambda) (Eq. 1) to an ``arviz.InferenceData``.

    Args:
        samples: ``(chains, draws, N)`` 0/1 indicators, numpy or torch (bool, int or float).
            For a single chain pass ``samples[None]``.
        names: the N sub-goal names, in indicator order; they become the ``subgoal`` coordinate.
        log_q: optional ``(chains, draws)`` values of log q(w) (unnormalised is fine) per draw.
        edges: optional MRF edges ``(u, v)`` or ``(u, v, sign)`` by sub-goal name; adds ``pair``.

    Returns:
        InferenceData with a ``posterior`` group holding ``w`` (int8, because ArviZ's summary
        fails on bool), ``log_q`` and ``pair`` as described in the module docstring.

    Raises:
        ValueError: wrong rank or shape, names/edges that do not match, non-binary or
            non-finite values; the message names the argument and the fix.
    """
    w = _to_numpy(samples, "samples")
    if w.ndim != 3:
        hint = " (for a single chain pass samples[None])" if w.ndim == 2 else ""
        raise ValueError(f"samples must have shape (chains, draws, N), got shape {w.shape}{hint}")
    chains, draws, n = w.shape
    if chains < 1 or draws < 1 or n < 1:
        raise ValueError(f"samples must have at least one chain, draw and sub-goal, got shape {w.shape}")
    if w.dtype.kind not in "biuf":
        raise ValueError(f"samples must be numeric 0/1 indicators, got dtype {w.dtype}")
    if not np.isin(w, (0, 1)).all():
        bad = np.unique(w[~np.isin(w, (0, 1))])[:5]
        raise ValueError(
            f"samples must be binary indicators (0/1), found other values such as {bad.tolist()}; "
            "pass the sampled w, not probabilities or logits"
        )
    w = w.astype(np.int8)
    names = _check_names(names, n)

    posterior: dict[str, np.ndarray] = {"w": w}
    dims: dict[str, list[str]] = {"w": ["subgoal"]}
    coords: dict[str, list[str]] = {"subgoal": names}

    if log_q is not None:
        lq = _to_numpy(log_q, "log_q")
        if lq.shape != (chains, draws):
            raise ValueError(
                f"log_q must have shape (chains, draws) = {(chains, draws)} to match samples, got {lq.shape}"
            )
        if lq.dtype.kind not in "iuf":
            raise ValueError(f"log_q must be real-valued, got dtype {lq.dtype}")
        lq = lq.astype(np.float64)
        if not np.isfinite(lq).all():
            # A drawn state has q(w) > 0, so a non-finite log q means a bug upstream.
            raise ValueError("log_q must be finite for every draw; a sampled state cannot have q(w) = 0")
        posterior["log_q"] = lq

    if edges is not None:
        pairs = _check_edges(edges, names)
        if pairs:
            col = {name: i for i, name in enumerate(names)}
            u_idx = np.array([col[u] for u, _ in pairs])
            v_idx = np.array([col[v] for _, v in pairs])
            posterior["pair"] = (w[..., u_idx] * w[..., v_idx]).astype(np.int8)
            dims["pair"] = ["edge"]
            coords["edge"] = [edge_label(u, v) for u, v in pairs]

    return az.from_dict(posterior=posterior, dims=dims, coords=coords)


def summary(idata: az.InferenceData, var_names: Sequence[str] = ("w",)) -> pd.DataFrame:
    """Per-sub-goal posterior summary: mean, sd, ess_bulk, ess_tail, r_hat, constant.

    ``mean`` of ``w`` is the marginal P(w_i = 1) under the sampled critic (Eq. 1); ``r_hat`` is
    ArviZ's rank-normalised split R-hat and ``ess_*`` its bulk/tail effective sample sizes, all
    unrounded. Rows are ArviZ's labels, e.g. ``w[yellow_key]``, ``pair[a--b]``, ``log_q``.

    ``constant`` is True where every draw of every chain has the same value. There R-hat is
    undefined (NaN: zero within- and between-chain variance) although all chains agree -- the usual
    case for a sub-goal the critic is certain about -- so read ``constant`` before flagging NaN.
    Where every chain is constant but the chains disagree, R-hat is reported as +inf.
    """
    if not isinstance(idata, az.InferenceData) or "posterior" not in idata.groups():
        raise ValueError("idata must be an arviz.InferenceData with a posterior group (see to_inference_data)")
    if isinstance(var_names, str):
        var_names = (var_names,)
    available = list(idata.posterior.data_vars)
    missing = [v for v in var_names if v not in available]
    if missing:
        raise ValueError(f"var_names {missing} not in the posterior; available variables: {available}")
    with warnings.catch_warnings():
        # Zero within-chain variance (constant or stuck chains) divides by zero inside ArviZ's
        # R-hat/MCSE; the result (NaN or a huge R-hat) and the `constant` column report it.
        warnings.filterwarnings(
            "ignore",
            message=r"(invalid value|divide by zero) encountered in (scalar )?(divide|sqrt)",
            category=RuntimeWarning,
            module=r"arviz\.stats\.diagnostics",
        )
        table = az.summary(idata, var_names=list(var_names), kind="all", round_to="none")
    table = table[_AZ_SUMMARY_COLUMNS].copy()
    constant, stuck = [], []
    for var in var_names:
        da = idata.posterior[var].transpose("chain", "draw", ...)
        vals = da.values.reshape(da.sizes["chain"], da.sizes["draw"], -1)
        each_chain_constant = (vals == vals[:, :1]).all(axis=(0, 1))
        all_equal = (vals == vals[:1, :1]).all(axis=(0, 1))
        constant.extend(all_equal.tolist())
        stuck.extend((each_chain_constant & ~all_equal).tolist())
    table["constant"] = constant
    # Every chain frozen but chains disagree: within-chain variance W = 0 < B, so R-hat =
    # sqrt((B/W + n - 1)/n) is +inf. ArviZ 0.23 returns NaN there (0/0 in its folded R-hat),
    # which a `r_hat > 1.01` check would silently pass.
    table.loc[np.asarray(stuck), "r_hat"] = np.inf
    return table


def save_netcdf(idata: az.InferenceData, path: str | os.PathLike[str]) -> Path:
    """Write ``idata`` to ``path`` as netCDF, atomically (temp file + ``os.replace``)."""
    if not isinstance(idata, az.InferenceData):
        raise ValueError(f"idata must be an arviz.InferenceData, got {type(idata).__name__}")
    with atomic_path(path, suffix=".nc") as tmp:
        idata.to_netcdf(str(tmp))
    return Path(path)


def load_netcdf(path: str | os.PathLike[str]) -> az.InferenceData:
    """Read a posterior written by :func:`save_netcdf` fully into memory (the file is closed)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no netCDF posterior at {path}; write one with save_netcdf(idata, path)")
    return az.from_netcdf(str(path))
