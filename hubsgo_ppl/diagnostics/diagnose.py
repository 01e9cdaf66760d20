"""``hubsgo diagnose RUN_DIR``: ArviZ checks and pictures of a HUBS-GO run's indicator posterior.

Draws several independent MH chains from the trained critic, converts them to ArviZ data, and writes
into ``RUN_DIR/diagnostics/``: ``summary.csv`` (mean, sd, ess_bulk, ess_tail, r_hat per sub-goal),
``trace.png``, ``forest.png``, ``posterior.png``, ``mrf_graph.png`` (the learned MRF),
``marginals.png`` (P(w_i = 1) over training, from ``critic_history.csv``, with the marginals of the
critic G* is read from, the settled refit where the agent settled, as stars) and ``posterior.nc``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..experiments.io import RunFileError
from ..experiments.logger import read_csv_rows
from ..experiments.run import RunError, load_run
from .arviz import save_netcdf, summary, to_inference_data
from .plots import plot_forest, plot_marginals_history, plot_mrf_graph, plot_posterior, plot_trace

__all__ = ["diagnose"]


def diagnose(run_dir: str | Path, chains: int = 4, draws: int = 2000, burn_in: int = 256,
             out: str | Path | None = None) -> dict[str, Any]:
    """Run the diagnostics; returns the summary table and the paths written."""
    if chains < 2:
        raise RunError(f"--chains must be at least 2 for r_hat, got {chains}")
    run_dir = Path(run_dir)
    resolved, env, agent, _ = load_run(run_dir)
    env.close()
    if not (hasattr(agent, "filter") and hasattr(agent.filter, "critic")):
        raise RunError(f"{run_dir}: agent {resolved['agent']!r} has no sub-goal critic to diagnose; "
                       "train with --agent hubsgo")
    critic = agent.g_star_critic()         # the posterior G* is read from (loop.settle_at)
    names = list(critic.names)
    out = Path(out) if out else run_dir / "diagnostics"
    out.mkdir(parents=True, exist_ok=True)

    samples = critic.sample(draws, num_chains=chains, burn_in=burn_in)          # (chains, draws, N)
    log_q = critic.log_q(samples.reshape(-1, len(names))).reshape(chains, draws)
    edges = [(u, v) for u, v, _ in critic.graph.edges]
    idata = to_inference_data(samples, names, log_q=log_q, edges=edges or None)
    table = summary(idata)
    paths: dict[str, Path] = {}
    from ..experiments.io import write_text

    paths["summary"] = write_text(out / "summary.csv", table.to_csv())
    paths["trace"] = plot_trace(idata, out / "trace.png")
    paths["forest"] = plot_forest(idata, out / "forest.png")
    paths["posterior"] = plot_posterior(idata, out / "posterior.png")
    factors = critic.factors()
    paths["mrf_graph"] = plot_mrf_graph(names, critic.marginals().detach().numpy(), edges,
                                        factors["pairwise"], out / "mrf_graph.png",
                                        title=f"learned critic: {resolved['task']} ({resolved.get('model', '')})")
    rows = read_csv_rows(run_dir / "critic_history.csv", required=("env_steps",))
    # the last row (critic=settled or final) holds the marginals of the critic G* is read from
    ends = [r for r in rows if r.get("critic") in ("settled", "final")]
    rows = [r for r in rows if r.get("critic") in (None, "", "training")]
    if rows:
        def number(text: str | None) -> float:     # a sub-goal a revision added has no value before it
            return float(text) if text not in (None, "") else float("nan")

        try:
            steps = np.array([float(r["env_steps"]) for r in rows])
            marg = np.array([[number(r.get(n)) for n in names] for r in rows])
            end = np.array([number(ends[-1].get(n)) for n in names]) if ends else None
            end_step = float(ends[-1]["env_steps"]) if ends else None
        except ValueError as exc:
            raise RunFileError(f"{run_dir / 'critic_history.csv'}: damaged, a value is not a number ({exc})") from None
        label = ("settled refit (G*)" if ends and ends[-1]["critic"] == "settled" else "end of training (G*)")
        paths["marginals"] = plot_marginals_history(steps, marg, names, out / "marginals.png",
                                                    end=end if end is not None and np.isfinite(end).all() else None,
                                                    end_step=end_step, end_label=label)
    paths["netcdf"] = save_netcdf(idata, out / "posterior.nc")
    return {"summary": table, "paths": paths, "chains": chains, "draws": draws}
