"""Diagnostics of the critic's indicator posterior q(w; lambda) (Eq. 1): ArviZ conversion,
per-sub-goal summaries, netCDF IO (:mod:`.arviz`) and pictures (:mod:`.plots`)."""

from hubsgo_ppl.diagnostics.arviz import load_netcdf, save_netcdf, summary, to_inference_data
from hubsgo_ppl.diagnostics.plots import (
    plot_forest,
    plot_marginals_history,
    plot_mrf_graph,
    plot_posterior,
    plot_trace,
)

__all__ = [
    "to_inference_data",
    "summary",
    "save_netcdf",
    "load_netcdf",
    "plot_trace",
    "plot_forest",
    "plot_posterior",
    "plot_mrf_graph",
    "plot_marginals_history",
]
