"""Cheap provenance handling for TraceGraph_ELBO.

TraceGraph_ELBO tags each non-reparameterised sample with a provenance set and finds the costs that
depend on it by propagating that set through every torch op (``pyro.ops.provenance``). Each such op
costs a pytree flatten, which dominates a small critic update. The helpers here strip the tag at
the start of a log-density computation and put the same tag on the result: same dependency
information, one tagged op instead of dozens.
"""

from __future__ import annotations

import torch
from pyro.distributions import TorchDistribution
from pyro.ops.provenance import ProvenanceTensor, detach_provenance, get_provenance, track_provenance

__all__ = ["untrack", "retrack", "WithProvenance", "to_batch_shape"]


def untrack(x: torch.Tensor) -> tuple[torch.Tensor, frozenset]:
    """``(plain tensor, provenance)``; plain tensors pass through with an empty provenance."""
    if isinstance(x, ProvenanceTensor):
        return detach_provenance(x), get_provenance(x)
    return x, frozenset()


def to_batch_shape(lp: torch.Tensor, batch_shape: torch.Size) -> torch.Tensor:
    """``lp`` expanded to broadcast with a distribution's batch shape; as it is when it already has that
    shape (no broadcast_shapes call, which a trace would record as ops)."""
    if lp.shape == batch_shape:
        return lp
    return lp.expand(torch.broadcast_shapes(lp.shape, batch_shape))


def retrack(x: torch.Tensor, provenance: frozenset) -> torch.Tensor:
    """Tag ``x`` with ``provenance`` (no-op for an empty set)."""
    return track_provenance(x, provenance) if provenance else x


class WithProvenance(TorchDistribution):
    """Wraps ``base`` so that its ``log_prob`` carries ``provenance``: the cost depends on those sites
    even though ``base`` was built from untracked parameters."""

    def __init__(self, base: TorchDistribution, provenance: frozenset):
        self.base = base
        self.provenance = provenance
        super().__init__(base.batch_shape, base.event_shape, validate_args=False)

    @property
    def support(self):
        return self.base.support

    def expand(self, batch_shape, _instance=None):
        return type(self)(self.base.expand(batch_shape), self.provenance)

    def sample(self, sample_shape=torch.Size()):
        return self.base.sample(sample_shape)

    def log_prob(self, value):
        return retrack(self.base.log_prob(untrack(value)[0]), self.provenance)
