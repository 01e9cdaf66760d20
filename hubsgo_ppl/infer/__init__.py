"""Inference for the HUBS-GO critic: MH kernels, prior/likelihood registries and the critic itself.

Exports load lazily: ``hubsgo_ppl.infer.mh`` sits below ``distributions.mrf`` in the layering, so this
package must not import the critic (which imports the MRF) just because the kernels were imported.
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
    "InferenceConfig": "critic",
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
