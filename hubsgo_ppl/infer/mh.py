"""The MH kernels of :mod:`hubsgo_ppl.distributions.mh_kernels` as a Pyro :class:`MCMCKernel`.

The kernels themselves (:func:`single_site_sweep`, :func:`block_flip_step`, :func:`run_chains`, ...)
live with the distribution that samples with them; they are re-exported here, where the critic and
:class:`MRFMHKernel` use them.
"""

from __future__ import annotations

import hashlib
import os

import torch
from pyro.infer.mcmc.mcmc_kernel import MCMCKernel

from ..distributions.mh_kernels import (  # noqa: F401  (_check, _eager_sweeps: used by tests and benchmarks)
    KERNELS,
    ChromaticScan,
    _check,
    _eager_sweeps,
    block_flip_step,
    coupling_matrix,
    mh_steps,
    run_chains,
    single_site_sweep,
    unnormalized_log_prob,
)

from ..distributions import mh_kernels as _kernels  # noqa: E402

__all__ = [*_kernels.__all__, "MRFMHKernel"]     # the kernels, re-exported, and the Pyro adapter


class MRFMHKernel(MCMCKernel):
    """Our MH kernels as a :class:`pyro.infer.mcmc.MCMCKernel`, for :class:`pyro.infer.MCMC`.

    The single site ``site`` holds w in {0,1}^N. There is no constrained-space transform
    (``transforms = {}``). Each :meth:`sample` call runs ``steps_per_sample`` sweeps.

    Randomness: each chain's generator is seeded from ``seed`` and the setup count (sequential chains
    in one process), so the same ``seed`` gives the same draws in every process; in the worker
    processes of ``num_chains > 1``, also from ``torch.initial_seed()``, which :class:`pyro.infer.MCMC`
    sets per chain there. Nothing is drawn from the global RNG. The kernel pickles without its
    generator, so ``num_chains > 1`` works with multiprocessing.

    >>> import torch, pyro
    >>> k = MRFMHKernel(torch.zeros(3), torch.ones(1), torch.tensor([[0, 1]]), seed=1)
    >>> mcmc = pyro.infer.MCMC(k, num_samples=5, warmup_steps=2, disable_progbar=True)
    >>> mcmc.run(); mcmc.get_samples()["w"].shape
    torch.Size([5, 3])
    """

    def __init__(
        self,
        theta: torch.Tensor,
        coupling: torch.Tensor,
        edge_index: torch.Tensor,
        kernel: str = "single_site",
        seed: int = 0,
        steps_per_sample: int = 1,
        block_size: int = 3,
        site: str = "w",
    ):
        if kernel not in KERNELS:
            raise ValueError(f"unknown MH kernel {kernel!r}; use one of: {', '.join(KERNELS)}")
        if theta.dim() != 1:
            raise ValueError(f"theta must have shape (N,), got {tuple(theta.shape)}")
        _check(theta.new_zeros(theta.shape), theta, coupling, edge_index)
        if steps_per_sample < 1:
            raise ValueError(f"steps_per_sample must be >= 1, got {steps_per_sample}")
        self.theta = theta.detach().clone()
        self.coupling = coupling.detach().clone()
        self.edge_index = edge_index.clone()
        self.kernel = kernel
        self.seed = int(seed)
        self.steps_per_sample = steps_per_sample
        self.block_size = block_size
        self.site = site
        self.transforms = {}
        self._initial = None
        self._setups = 0
        self._pid = os.getpid()     # the process that built it draws from ``seed`` alone
        self._generator = None
        self._accepted = 0
        self._flips = 0

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_generator"] = None
        return state

    def setup(self, warmup_steps, *args, **kwargs):
        # torch's initial seed differs from process to process unless the user sets it: only a worker's,
        # which pyro.infer.MCMC sets per chain, tells the chains of one run apart
        stream = 0 if os.getpid() == self._pid else torch.initial_seed()
        key = f"{self.seed}:{self._setups}:{stream}".encode()
        self._setups += 1
        self._generator = torch.Generator().manual_seed(int.from_bytes(hashlib.sha256(key).digest()[:7], "little"))
        self._accepted = self._flips = 0

    @property
    def initial_params(self):
        if self._initial is not None:
            return {self.site: self._initial.clone()}
        if self._generator is None:
            self.setup(0)
        n = self.theta.shape[0]
        return {self.site: torch.randint(0, 2, (n,), generator=self._generator).to(self.theta.dtype)}

    @initial_params.setter
    def initial_params(self, params):
        w = params[self.site]
        if w.shape != self.theta.shape or not bool(((w == 0) | (w == 1)).all()):
            raise ValueError(f"initial {self.site!r} must be a 0/1 tensor of shape {tuple(self.theta.shape)}")
        self._initial = w.to(self.theta.dtype)

    def sample(self, params):
        if self._generator is None:
            self.setup(0)
        w = params[self.site]
        new = mh_steps(w, self.theta, self.coupling, self.edge_index, self._generator, self.steps_per_sample, self.kernel, self.block_size)
        self._flips += 1
        self._accepted += int(bool((new != w).any()))
        return {self.site: new}

    def logging(self):
        return {"moved": round(self._accepted / max(self._flips, 1), 3)}

    def diagnostics(self):
        return {"fraction_moved": self._accepted / max(self._flips, 1)}
