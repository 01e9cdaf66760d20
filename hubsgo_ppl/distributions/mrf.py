"""The pairwise binary MRF of Eq. 1 as a Pyro distribution: the HUBS-GO critic q(w; lambda).

    log q(w) = theta . w + sum_{(u,v) in E} J_uv w_u w_v - log Z(theta, J),   w in {0,1}^N

The unary factors psi_j(w_j) = theta_j w_j and pairwise factors phi_uv(w_u, w_v) = J_uv w_u w_v are
the paper's potentials (any binary pairwise potential reduces to this form up to a constant).

Normalisation. For N <= ``exact_max_n`` (at most 20), ``log Z``, marginals and the normalised
``log_prob`` come from vectorised enumeration of all 2^N states in chunks of 2^16. Above that,
``log_prob`` returns the unnormalised log q~ (off by the constant log Z) and :meth:`score_parts`
replaces the score with the leave-one-out estimator over the vectorised particles (dim 0)::

    score(w_p) = log q~(w_p) - mean_{q != p} log q~(w_q)

whose gradient, s(w_p) - mean_{q != p} s(w_q) with s the sufficient statistics, is an unbiased
estimate of the normalised score s(w_p) - E_q[s] = grad log q(w_p), i.e. grad log Z is taken as the
mean sufficient statistics of the other (independent) particles. It needs >= 2 particles.

Sampling runs the MH kernels of :mod:`hubsgo_ppl.distributions.mh_kernels` under ``no_grad`` for
``burn_in`` sweeps, starting from ``init`` (persistent chains) when given, else from uniform random bits.
"""

from __future__ import annotations

import functools

import torch
from pyro.distributions import TorchDistribution
from pyro.distributions.score_parts import ScoreParts
from torch.distributions import constraints

from ._provenance import retrack, to_batch_shape, untrack
from .mh_kernels import KERNELS, coupling_matrix, mh_steps, unnormalized_log_prob

__all__ = ["PairwiseMRF", "state_table", "EXACT_LIMIT"]

EXACT_LIMIT = 20  # 2^20 states; enumeration beyond this costs seconds per call (2.7 s at N = 22)
_CHUNK_BITS = 16
_CACHED_TABLE_BITS = 16


@functools.lru_cache(maxsize=32)
def _cached_table(n: int, dtype: torch.dtype) -> torch.Tensor:
    return _states(0, 2**n, n, dtype)


def _states(start: int, stop: int, n: int, dtype: torch.dtype) -> torch.Tensor:
    codes = torch.arange(start, stop, dtype=torch.long)
    return ((codes.unsqueeze(-1) >> torch.arange(n)) & 1).to(dtype)


def state_table(n: int, dtype: torch.dtype = torch.float32) -> torch.Tensor:
    """All 2^N states as a ``(2^N, N)`` 0/1 tensor; row k has w_i = bit i of k. Cached for N <= 16."""
    if n > EXACT_LIMIT:
        raise ValueError(f"enumerating 2^{n} states is too costly; exact answers are limited to N <= {EXACT_LIMIT}")
    return _cached_table(n, dtype) if n <= _CACHED_TABLE_BITS else _states(0, 2**n, n, dtype)


def _chunks(n: int, dtype: torch.dtype):
    if n <= _CACHED_TABLE_BITS:
        yield _cached_table(n, dtype)
        return
    step = 2**_CHUNK_BITS
    for start in range(0, 2**n, step):
        yield _states(start, start + step, n, dtype)


class PairwiseMRF(TorchDistribution):
    """Pairwise binary MRF over w in {0,1}^N (Eq. 1); see the module docstring.

    :param theta: unary factors, ``(..., N)``.
    :param coupling: pairwise factors J, ``(..., E)``, one per row of ``edge_index``.
    :param edge_index: ``(E, 2)`` LongTensor of distinct site pairs.
    :param burn_in: MH sweeps run by :meth:`sample` (paper: 32).
    :param kernel: ``"single_site"`` or ``"block"`` (see :mod:`hubsgo_ppl.distributions.mh_kernels`).
    :param init: chain states to start :meth:`sample` from, broadcastable to the sample's shape.
    :param generator: torch.Generator for sampling; a generator seeded with 0 if None.
    :param exact_max_n: largest N (<= 20) handled by exact enumeration.
    """

    arg_constraints = {"theta": constraints.real_vector, "coupling": constraints.real_vector}
    support = constraints.independent(constraints.boolean, 1)
    has_enumerate_support = True

    def __init__(
        self,
        theta: torch.Tensor,
        coupling: torch.Tensor,
        edge_index: torch.Tensor,
        *,
        burn_in: int = 32,
        kernel: str = "single_site",
        init: torch.Tensor | None = None,
        generator: torch.Generator | None = None,
        exact_max_n: int = EXACT_LIMIT,
        validate_args: bool | None = None,
        batch_shape: torch.Size | tuple[int, ...] | None = None,
    ):
        if theta.dim() < 1 or theta.shape[-1] < 1:
            raise ValueError(f"theta must have shape (..., N) with N >= 1, got {tuple(theta.shape)}")
        n = theta.shape[-1]
        edge_index = torch.as_tensor(edge_index, dtype=torch.long)
        if edge_index.dim() != 2:
            edge_index = edge_index.reshape(-1, 2)
        if coupling.dim() < 1 or coupling.shape[-1] != edge_index.shape[0]:
            raise ValueError(
                f"coupling must have shape (..., E) with E = {edge_index.shape[0]} edges, got {tuple(coupling.shape)}"
            )
        checked = validate_args is not False  # the critic's own guides (validate_args=False) skip these
        if edge_index.numel() and checked:
            if int(edge_index.min()) < 0 or int(edge_index.max()) >= n:
                raise ValueError(f"edge_index refers to a site outside 0..{n - 1}")
            if bool((edge_index[:, 0] == edge_index[:, 1]).any()):
                raise ValueError("edge_index has a self-edge (u, u); edges must join two different sites")
            pairs = {tuple(sorted(p)) for p in edge_index.tolist()}
            if len(pairs) != edge_index.shape[0]:
                raise ValueError("edge_index lists a pair twice; give each edge once")
        if kernel not in KERNELS:
            raise ValueError(f"unknown MH kernel {kernel!r}; use one of: {', '.join(KERNELS)}")
        if int(burn_in) != burn_in or burn_in < 0:
            raise ValueError(f"burn_in must be a non-negative integer, got {burn_in!r}")
        if not 0 <= exact_max_n <= EXACT_LIMIT:
            raise ValueError(f"exact_max_n must be in 0..{EXACT_LIMIT}, got {exact_max_n}")
        natural = theta.shape[:-1]
        if coupling.shape[:-1] != natural:
            natural = torch.broadcast_shapes(natural, coupling.shape[:-1])
        batch_shape = natural if batch_shape is None else torch.Size(batch_shape)
        if batch_shape != natural and torch.broadcast_shapes(natural, batch_shape) != batch_shape:
            raise ValueError(f"cannot expand parameters of batch shape {tuple(natural)} to {tuple(batch_shape)}")
        if init is not None:
            init = init.detach()
            if init.shape[-1] != n or (checked and not bool(((init == 0) | (init == 1)).all())):
                raise ValueError(f"init must be a 0/1 tensor of shape (..., {n})")
        # Parameters are kept unexpanded: an expanded copy per particle would turn the MH field
        # update into a batched matmul and the enumeration into one log Z per particle.
        self.theta = theta
        self.coupling = coupling
        self.edge_index = edge_index
        self.burn_in = int(burn_in)
        self.kernel = kernel
        self.init = init
        self.generator = generator if generator is not None else torch.Generator().manual_seed(0)
        self.exact_max_n = int(exact_max_n)
        self._cache: dict = {}
        super().__init__(batch_shape, torch.Size([n]), validate_args=validate_args)

    @property
    def n(self) -> int:
        return int(self.event_shape[0])

    @property
    def is_exact(self) -> bool:
        return self.n <= self.exact_max_n

    def expand(self, batch_shape, _instance=None):
        # Must return type(self)(...): Pyro's vectorised particles call expand(), and a generic
        # expanded instance would silently lose the score_parts override.
        new = type(self)(
            self.theta,
            self.coupling,
            self.edge_index,
            burn_in=self.burn_in,
            kernel=self.kernel,
            init=self.init,
            generator=self.generator,
            exact_max_n=self.exact_max_n,
            validate_args=self._validate_args,
            batch_shape=torch.Size(batch_shape),
        )
        new._cache = self._cache  # same parameters, same log Z
        return new

    def _matrix(self) -> torch.Tensor:
        if "mat" not in self._cache:
            self._cache["mat"] = coupling_matrix(self.coupling, self.edge_index, self.n)
        return self._cache["mat"]

    def unnormalized_log_prob(self, value: torch.Tensor) -> torch.Tensor:
        """theta . w + sum J_uv w_u w_v, shape ``value.shape[:-1]`` broadcast with the batch shape."""
        value, prov = untrack(value)
        lp = unnormalized_log_prob(value.to(self.theta.dtype), self.theta, self._matrix())
        return retrack(to_batch_shape(lp, self.batch_shape) if self.batch_shape else lp, prov)

    def _require_exact(self, what: str) -> None:
        if not self.is_exact:
            raise ValueError(
                f"{what} needs enumeration of 2^{self.n} states but exact_max_n = {self.exact_max_n}; "
                f"raise exact_max_n (<= {EXACT_LIMIT}) or use sample-based estimates"
            )

    def _log_weights_by_chunk(self):
        mat = self._matrix()
        for states in _chunks(self.n, self.theta.dtype):
            # (..., K): batch dims of the parameters, K states of this chunk
            lin = states @ self.theta.unsqueeze(-1)
            pair = ((states @ mat) * states).sum(-1, keepdim=True)
            yield (lin + 0.5 * pair).squeeze(-1), states

    def log_partition(self) -> torch.Tensor:
        """Exact log Z by chunked enumeration, shape = the parameters' batch shape (differentiable)."""
        self._require_exact("log_partition")
        if "log_z" not in self._cache:
            parts = [torch.logsumexp(lw, -1) for lw, _ in self._log_weights_by_chunk()]
            self._cache["log_z"] = parts[0] if len(parts) == 1 else torch.logsumexp(torch.stack(parts, -1), -1)
        return self._cache["log_z"]

    def log_prob(self, value: torch.Tensor) -> torch.Tensor:
        """Normalised log q(w) for N <= exact_max_n, else the unnormalised log q~(w) (see module doc).

        The result for the last ``value`` tensor is cached with log Z (same parameters, same answer), so
        a second call on the same samples, e.g. the critic's entropy diagnostic after Pyro's own
        ``log_prob``, costs nothing."""
        value, prov = untrack(value)
        cached = self._cache.get("log_prob")
        if cached is not None and cached[0] is value and (not self.batch_shape or self.batch_shape == value.shape[:-1]):
            return retrack(cached[1], prov)
        if self._validate_args:
            self._validate_sample(value)
        lp = self.unnormalized_log_prob(value)
        if self.is_exact:
            lp = lp - self.log_partition()
        self._cache["log_prob"] = (value, lp)
        return retrack(lp, prov)

    def score_parts(self, value: torch.Tensor) -> ScoreParts:
        """Score-function parts for TraceGraph_ELBO (Eq. 5): exact, or leave-one-out above exact_max_n."""
        if self.is_exact:
            lp = self.log_prob(value)
            return ScoreParts(log_prob=lp, score_function=lp, entropy_term=0)
        value, prov = untrack(value)
        lq = self.unnormalized_log_prob(value)
        p = lq.shape[0] if lq.dim() else 1
        if p < 2:
            raise ValueError(
                f"the leave-one-out score for N = {self.n} > exact_max_n needs >= 2 independent particles "
                "along dim 0 (e.g. TraceGraph_ELBO(num_particles=64, vectorize_particles=True))"
            )
        loo = lq - (lq.sum(0, keepdim=True) - lq) / (p - 1)
        return ScoreParts(log_prob=retrack(lq, prov), score_function=retrack(loo, prov), entropy_term=0)

    def probs(self) -> torch.Tensor:
        """Probabilities of all 2^N states, ``(..., 2^N)`` in :func:`state_table` order."""
        self._require_exact("probs")
        log_z = self.log_partition()
        return torch.cat([torch.exp(lw - log_z.unsqueeze(-1)) for lw, _ in self._log_weights_by_chunk()], -1)

    def marginals(self) -> torch.Tensor:
        """Exact P(w_i = 1), ``(..., N)``."""
        self._require_exact("marginals")
        log_z = self.log_partition().unsqueeze(-1)
        total = 0.0
        for lw, states in self._log_weights_by_chunk():
            total = total + torch.exp(lw - log_z) @ states
        return total

    def entropy(self) -> torch.Tensor:
        self._require_exact("entropy")
        log_z = self.log_partition().unsqueeze(-1)
        total = 0.0
        for lw, _ in self._log_weights_by_chunk():
            lp = lw - log_z
            total = total - (torch.exp(lp) * lp).sum(-1)
        return total

    def enumerate_support(self, expand: bool = True) -> torch.Tensor:
        """All 2^N states, ``(2^N, *batch_shape, N)`` (or ``(2^N, 1, ..., 1, N)`` without expand)."""
        self._require_exact("enumerate_support")
        states = state_table(self.n, self.theta.dtype)
        shape = (states.shape[0],) + (1,) * len(self.batch_shape) + (self.n,)
        states = states.reshape(shape)
        if expand:
            states = states.expand((states.shape[0],) + self.batch_shape + (self.n,))
        return states

    def sample(self, sample_shape=torch.Size()) -> torch.Tensor:
        """``burn_in`` MH sweeps from ``init`` (or random bits); returns 0/1 floats of
        ``sample_shape + batch_shape + (N,)``. Runs under ``no_grad``."""
        shape = self._extended_shape(sample_shape)
        with torch.no_grad():
            theta, coupling = self.theta.detach(), self.coupling.detach()
            if self.init is not None:
                try:
                    w = self.init.to(theta.dtype).expand(shape)
                except RuntimeError:
                    raise ValueError(
                        f"init of shape {tuple(self.init.shape)} does not broadcast to the sample shape {tuple(shape)}"
                    ) from None
            else:
                w = torch.randint(0, 2, shape, generator=self.generator).to(theta.dtype)
            return mh_steps(w, theta, coupling, self.edge_index, self.generator, self.burn_in, self.kernel)

    @property
    def mean(self) -> torch.Tensor:
        return self.marginals()

    @property
    def variance(self) -> torch.Tensor:
        m = self.marginals()
        return m * (1 - m)

    def __repr__(self) -> str:
        return f"PairwiseMRF(n={self.n}, edges={self.edge_index.shape[0]}, batch_shape={tuple(self.batch_shape)})"


