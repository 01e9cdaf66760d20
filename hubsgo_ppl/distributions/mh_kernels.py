"""Metropolis-Hastings kernels for the pairwise binary MRF of Eq. 1, written in plain torch (and numba).

The paper (Sec. 3.3) draws the critic's samples with an MH sampler: burn-in of 32 steps, then 64
samples per update. Two kernels live here, as pure functions of ``(theta, coupling, edge_index)``:

* :func:`single_site_sweep`: one sweep visits every site once and proposes flipping it, accepted
  with min(1, q(w')/q(w)). Sites that share no edge are conditionally independent, so each colour
  class of the graph is flipped in one vectorised step (a chromatic scan): an independent graph
  costs one step per sweep, a fully connected one N.
* :func:`block_flip_step`: proposes flipping a single site, both ends of a random edge, or a random
  block of sites, with the MH accept. It moves between modes that single flips must cross through
  low-probability states (e.g. {key, door} -> {other key, other door}).

Both are batched: ``w`` is ``(..., N)`` with any number of leading chain/batch dimensions, and all
randomness comes from an explicit ``torch.Generator``. :func:`run_chains` records whole chains.

They sit with the distribution that samples with them (:class:`~hubsgo_ppl.distributions.PairwiseMRF`);
the adapter to :class:`pyro.infer.MCMC` is :class:`hubsgo_ppl.infer.mh.MRFMHKernel`.
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
import torch

from ..graph import colour_classes

__all__ = [
    "KERNELS",
    "ChromaticScan",
    "coupling_matrix",
    "unnormalized_log_prob",
    "single_site_sweep",
    "block_flip_step",
    "mh_steps",
    "run_chains",
]

KERNELS = ("single_site", "block")


def coupling_matrix(coupling: torch.Tensor, edge_index: torch.Tensor, n: int) -> torch.Tensor:
    """Symmetric ``(..., N, N)`` matrix with ``J_uv`` at both ``(u, v)`` and ``(v, u)``, zero diagonal."""
    mat = coupling.new_zeros(coupling.shape[:-1] + (n, n))
    if edge_index.numel():
        u, v = edge_index[:, 0], edge_index[:, 1]
        mat[..., u, v] = coupling
        mat[..., v, u] = coupling
    return mat


def unnormalized_log_prob(w: torch.Tensor, theta: torch.Tensor, mat: torch.Tensor) -> torch.Tensor:
    """log q~(w) = theta.w + sum_(u,v) J_uv w_u w_v (Eq. 1 without log Z), with ``mat`` from
    :func:`coupling_matrix` (each edge appears twice there, hence the 1/2)."""
    # with one matrix, w @ J is the same mm as the batched form (the same floats), in one op instead of three
    pair = (((w @ mat) if mat.dim() == 2 else (w.unsqueeze(-2) @ mat).squeeze(-2)) * w).sum(-1)
    return (w * theta).sum(-1) + 0.5 * pair


def _check(w: torch.Tensor, theta: torch.Tensor, coupling: torch.Tensor, edge_index: torch.Tensor) -> None:
    n = theta.shape[-1]
    if w.shape[-1] != n:
        raise ValueError(f"chain states have {w.shape[-1]} sites but theta has {n}; pass w of shape (..., {n})")
    if edge_index.dim() != 2 or edge_index.shape[-1] != 2:
        raise ValueError(f"edge_index must have shape (E, 2), got {tuple(edge_index.shape)}")
    if coupling.shape[-1] != edge_index.shape[0]:
        raise ValueError(
            f"coupling has {coupling.shape[-1]} entries but edge_index has {edge_index.shape[0]} edges; "
            "give one coupling per edge"
        )


@numba.njit(cache=True, nogil=True)
def _chromatic_sweeps(spin, field, log_u, classes, class_ptr, mat, nb, nb_ptr):  # pragma: no cover (compiled)
    """The sweeps of :func:`single_site_sweep` on flat chains, compiled with numba; in place.

    ``spin`` ``(S, N)`` = 1 - 2w, ``field`` ``(S, N)`` = theta + J w, ``log_u`` ``(T, S, N)`` (one
    sweep per row), ``classes[class_ptr[c]:class_ptr[c + 1]]`` the sites of colour class c in
    ascending order, ``mat`` the symmetric ``(N, N)`` coupling matrix, ``nb[nb_ptr[c]:nb_ptr[c + 1]]``
    the sites coupled to some site of class c. Only those fields are updated: elsewhere the eager loop
    adds an exact zero, so skipping it changes no value (a sweep costs O(S (N + E)), not O(S N^2)). The arithmetic is the eager
    loop's: accept where ``log u < spin * field``, ``spin -= 2 dw`` and ``field += dw J`` summed over
    the class in ascending site order, so both give the same floats (tests/infer/test_mh.py).
    """
    num_chains, n = spin.shape
    dw = np.zeros(n, dtype=spin.dtype)
    two = spin.dtype.type(2.0)
    for t in range(log_u.shape[0]):
        for c in range(class_ptr.shape[0] - 1):
            lo, hi = class_ptr[c], class_ptr[c + 1]
            for s in range(num_chains):
                flipped = False
                for q in range(lo, hi):
                    i = classes[q]
                    if log_u[t, s, i] < spin[s, i] * field[s, i]:
                        dw[i] = spin[s, i]
                        flipped = True
                if not flipped:
                    continue
                for q in range(lo, hi):
                    i = classes[q]
                    spin[s, i] -= two * dw[i]
                for k in range(nb_ptr[c], nb_ptr[c + 1]):
                    j = nb[k]
                    acc = spin.dtype.type(0.0)
                    for q in range(lo, hi):
                        acc += dw[classes[q]] * mat[classes[q], j]
                    field[s, j] += acc
                for q in range(lo, hi):
                    dw[classes[q]] = 0.0


_LOG_U_ELEMENTS = 1 << 22  # cap on one block of log-uniforms (16 MB in float32)
_RAND_BLOCK = 32  # most sweeps whose uniforms are drawn in one call (the same stream as one call per sweep)


@numba.njit(cache=True, nogil=True)
def _scan_state(w, theta, coupling, u, v):  # pragma: no cover (compiled)
    """``(spin, field, mat)`` for :func:`_chromatic_sweeps`, computed as the eager loop does: ``mat`` is
    :func:`coupling_matrix` (restated here because numba cannot call torch), J placed at (u, v) and (v, u), ``field = theta + w J`` summed in ascending site order (w is 0/1, so every
    product is exact), ``spin = 1 - 2w``."""
    num_chains, n = w.shape
    mat = np.zeros((n, n), dtype=theta.dtype)
    for e in range(u.shape[0]):
        mat[u[e], v[e]] = coupling[e]
        mat[v[e], u[e]] = coupling[e]
    field = np.empty((num_chains, n), dtype=theta.dtype)
    spin = np.empty((num_chains, n), dtype=theta.dtype)
    for s in range(num_chains):
        for j in range(n):
            acc = theta.dtype.type(0.0)
            for k in range(n):
                acc += w[s, k] * mat[k, j]
            field[s, j] = theta[j] + acc
            spin[s, j] = 1.0 - 2.0 * w[s, j]
    return spin, field, mat


class ChromaticScan:
    """:func:`single_site_sweep` for flat chains ``(S, N)`` on CPU for one graph, compiled with numba
    (:func:`_scan_state`, :func:`_chromatic_sweeps`), with the colour classes computed once. The result
    is identical to the eager loop's (tests/infer/test_mh.py checks it)."""

    def __init__(self, edge_index: torch.Tensor, n: int):
        edge_index = torch.as_tensor(edge_index, dtype=torch.long).reshape(-1, 2)
        self.n = int(n)
        self.u = edge_index[:, 0].numpy().copy()
        self.v = edge_index[:, 1].numpy().copy()
        classes = [sorted(idx.tolist()) for idx in colour_classes(edge_index, self.n)]
        self.classes = np.array([i for c in classes for i in c], dtype=np.int64)
        self.class_ptr = np.cumsum([0] + [len(c) for c in classes]).astype(np.int64)
        neighbours: list[set[int]] = [set() for _ in range(self.n)]
        for a, b in zip(self.u.tolist(), self.v.tolist()):
            neighbours[a].add(b)
            neighbours[b].add(a)
        per_class = [sorted(set().union(*(neighbours[i] for i in c))) if c else [] for c in classes]
        self.nb = np.array([j for c in per_class for j in c], dtype=np.int64)
        self.nb_ptr = np.cumsum([0] + [len(c) for c in per_class]).astype(np.int64)

    def __call__(self, w: torch.Tensor, theta: torch.Tensor, coupling: torch.Tensor,
                 generator: torch.Generator | None, sweeps: int = 1) -> torch.Tensor:
        dtype = theta.dtype
        spin, field, mat = _scan_state(w.detach().to(dtype).contiguous().numpy(), theta.detach().contiguous().numpy(),
                                       coupling.detach().to(dtype).contiguous().numpy(), self.u, self.v)
        step = max(1, min(_RAND_BLOCK, _LOG_U_ELEMENTS // max(w.numel(), 1)))
        for start in range(0, sweeps, step):
            block = min(step, sweeps - start)
            log_u = torch.rand((block,) + tuple(w.shape), generator=generator, dtype=dtype).log_()
            _chromatic_sweeps(spin, field, log_u.numpy(), self.classes, self.class_ptr, mat, self.nb, self.nb_ptr)
        return torch.from_numpy((1.0 - spin) * 0.5)


@functools.lru_cache(maxsize=64)
def _scan_for(pairs: tuple, n: int) -> ChromaticScan:
    return ChromaticScan(torch.tensor(pairs, dtype=torch.long).reshape(-1, 2), n)


def single_site_sweep(
    w: torch.Tensor,
    theta: torch.Tensor,
    coupling: torch.Tensor,
    edge_index: torch.Tensor,
    generator: torch.Generator | None,
    sweeps: int = 1,
) -> torch.Tensor:
    """Run ``sweeps`` chromatic single-site MH sweeps on the batched chains ``w`` (..., N); returns new w.

    Flipping site i changes log q by ``(1 - 2 w_i) * h_i`` with the local field
    ``h = theta + J w``; the field is updated incrementally after each colour class. Flat chains
    ``(S, N)`` with one parameter set on CPU (the critic's case) run compiled in :class:`ChromaticScan`,
    anything else in the eager torch loop; both give the same result.
    """
    _check(w, theta, coupling, edge_index)
    n = w.shape[-1]
    if _compiled_case(w, theta, coupling):
        return _scan_for(tuple(tuple(p) for p in edge_index.tolist()), n)(w, theta, coupling, generator, sweeps)
    return _eager_sweeps(w, theta, coupling, edge_index, generator, sweeps)


def _compiled_case(w: torch.Tensor, theta: torch.Tensor, coupling: torch.Tensor) -> bool:
    """Flat chains and one parameter set, on CPU in float32/64: what :class:`ChromaticScan` runs."""
    return (w.dim() == 2 and theta.dim() == 1 and coupling.dim() == 1 and w.device.type == "cpu"
            and theta.device.type == "cpu" and theta.dtype in (torch.float32, torch.float64))


def _eager_sweeps(w, theta, coupling, edge_index, generator, sweeps: int) -> torch.Tensor:
    """The reference loop of :func:`single_site_sweep` in plain torch (any batch shape or device)."""
    n = w.shape[-1]
    with torch.no_grad():
        mat = coupling_matrix(coupling, edge_index, n)
        w = w.to(theta.dtype)
        field = (theta + (w.unsqueeze(-2) @ mat).squeeze(-2)).expand(w.shape).clone()
        spin = 1.0 - 2.0 * w  # +1 where w = 0: flipping site i changes log q by spin_i * field_i
        # log-uniforms are pushed to +inf off the current colour class, so one comparison both
        # decides the MH accept and restricts the flips to that class (no gather/scatter).
        off_class = [torch.full((n,), math.inf, dtype=w.dtype, device=w.device).index_fill_(0, idx.to(w.device), 0.0)
                     for idx in colour_classes(edge_index, n)]
        has_edges = edge_index.numel() > 0
        flat = mat.dim() == 2 and w.dim() == 2
        for _ in range(sweeps):
            log_u = torch.rand(w.shape, generator=generator, dtype=w.dtype, device=w.device).log_()
            for mask in off_class:
                dw = (log_u + mask < spin * field) * spin
                spin.sub_(dw, alpha=2.0)
                if has_edges:
                    if flat:
                        field.addmm_(dw, mat)
                    else:
                        field += (dw.unsqueeze(-2) @ mat).squeeze(-2)
    return (1.0 - spin) * 0.5


def _block_masks(shape: torch.Size, n: int, edge_index: torch.Tensor, block_size: int, generator, device) -> torch.Tensor:
    lead = shape[:-1]
    kind = torch.randint(0, 3, lead, generator=generator, device=device)
    single = torch.zeros(shape, device=device)
    single.scatter_(-1, torch.randint(0, n, lead + (1,), generator=generator, device=device), 1.0)
    k = min(block_size, n)
    keys = torch.rand(shape, generator=generator, device=device)
    block = torch.zeros(shape, device=device).scatter_(-1, keys.topk(k, dim=-1).indices, 1.0)
    if edge_index.shape[0]:
        e = torch.randint(0, edge_index.shape[0], lead, generator=generator, device=device)
        pair = torch.zeros(shape, device=device).scatter_(-1, edge_index.to(device)[e], 1.0)
    else:
        pair = torch.zeros(shape, device=device).scatter_(-1, keys.topk(min(2, n), dim=-1).indices, 1.0)
    kind = kind.unsqueeze(-1)
    return torch.where(kind == 0, single, torch.where(kind == 1, pair, block))


def block_flip_step(
    w: torch.Tensor,
    theta: torch.Tensor,
    coupling: torch.Tensor,
    edge_index: torch.Tensor,
    generator: torch.Generator | None,
    steps: int = 1,
    block_size: int = 3,
) -> torch.Tensor:
    """Block-flip MH on the batched chains ``w`` (..., N); one step makes N proposals per chain.

    Each proposal flips, with probability 1/3 each, one random site, both ends of a random edge
    (a random pair if there are no edges) or ``block_size`` random sites. The proposal does not depend
    on ``w`` and is its own inverse, so it is symmetric and the accept is min(1, q(w')/q(w)).
    """
    _check(w, theta, coupling, edge_index)
    if block_size < 1:
        raise ValueError(f"block_size must be >= 1, got {block_size}")
    n = w.shape[-1]
    with torch.no_grad():
        mat = coupling_matrix(coupling, edge_index, n)
        w = w.to(theta.dtype).clone()
        logq = unnormalized_log_prob(w, theta, mat)
        for _ in range(steps * n):
            mask = _block_masks(w.shape, n, edge_index, block_size, generator, w.device).to(w.dtype)
            proposal = w + mask * (1.0 - 2.0 * w)
            logq_new = unnormalized_log_prob(proposal, theta, mat)
            u = torch.rand(logq.shape, generator=generator, dtype=w.dtype, device=w.device)
            accept = u < torch.exp(logq_new - logq)
            w = torch.where(accept.unsqueeze(-1), proposal, w)
            logq = torch.where(accept, logq_new, logq)
    return w


def mh_steps(w, theta, coupling, edge_index, generator, steps: int, kernel: str = "single_site", block_size: int = 3):
    """``steps`` sweeps of the named kernel ("single_site" or "block")."""
    if steps == 0:
        return w.to(theta.dtype).clone()
    if kernel == "single_site":
        return single_site_sweep(w, theta, coupling, edge_index, generator, sweeps=steps)
    if kernel == "block":
        return block_flip_step(w, theta, coupling, edge_index, generator, steps=steps, block_size=block_size)
    raise ValueError(f"unknown MH kernel {kernel!r}; use one of: {', '.join(KERNELS)}")


def run_chains(
    theta: torch.Tensor,
    coupling: torch.Tensor,
    edge_index: torch.Tensor,
    num_chains: int,
    num_steps: int,
    kernel: str = "single_site",
    init: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
    thin: int = 1,
    burn_in: int = 0,
) -> torch.Tensor:
    """Run ``num_chains`` chains as one tensor and record ``num_steps`` states each.

    Each recorded state follows ``thin`` sweeps; ``burn_in`` sweeps are discarded first. Chains start
    at ``init`` (``(num_chains, N)``) or at uniform random bits. Without ``generator`` a generator
    seeded with 0 is used, so pass one for independent streams.

    Returns a ``(num_chains, num_steps, N)`` float tensor of 0/1.
    """
    if theta.dim() != 1:
        raise ValueError(f"run_chains takes unbatched theta of shape (N,), got {tuple(theta.shape)}")
    if num_chains < 1 or num_steps < 0 or thin < 1 or burn_in < 0:
        raise ValueError(
            f"need num_chains >= 1, num_steps >= 0, thin >= 1, burn_in >= 0; got {num_chains}, {num_steps}, {thin}, {burn_in}"
        )
    if generator is None:
        generator = torch.Generator().manual_seed(0)
    n = theta.shape[-1]
    if init is None:
        w = torch.randint(0, 2, (num_chains, n), generator=generator).to(theta.dtype)
    else:
        if init.shape != (num_chains, n):
            raise ValueError(f"init must have shape ({num_chains}, {n}), got {tuple(init.shape)}")
        w = init.to(theta.dtype)
    theta, coupling = theta.detach(), coupling.detach()
    w = mh_steps(w, theta, coupling, edge_index, generator, burn_in, kernel)
    out = torch.empty(num_chains, num_steps, n, dtype=theta.dtype)
    for t in range(num_steps):
        w = mh_steps(w, theta, coupling, edge_index, generator, thin, kernel)
        out[:, t] = w
    return out
