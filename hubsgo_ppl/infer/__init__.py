"""Inference for the HUBS-GO critic: its settings, prior/likelihood registries, the Pyro MCMC kernel
adapter and the critic itself.

Exports load lazily, so that the light modules stay light to import: :mod:`.config` (pydantic only,
nested by :mod:`hubsgo_ppl.specs`) and :mod:`.tdbatch` (torch only, built by the agents) must not pull
in Pyro and the critic just because their package was imported.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "single_site_sweep": "mh",
    "block_flip_step": "mh",
    "run_chains": "mh",
    "MRFMHKernel": "mh",
    "ChromaticScan": "mh",
    "register_prior": "priors",
    "get_prior": "priors",
    "PRIORS": "priors",
    "Prior": "priors",
    "register_likelihood": "likelihoods",
    "get_likelihood": "likelihoods",
    "LIKELIHOODS": "likelihoods",
    "Likelihood": "likelihoods",
    "InferenceConfig": "config",
    "InferenceSpec": "config",
    "TDBatch": "tdbatch",
    "SubgoalCritic": "critic",
    "CompiledTraceGraph_ELBO": "compiled_elbo",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f".{_EXPORTS[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return __all__
