"""Priors p(w) over sub-goal indicators w in {0,1}^N (the p(w) of Eq. 3 and Eq. 5).

The paper's default is a uniform categorical over configurations, i.e. independent Bernoulli(0.5)
(``"bernoulli"``). Also registered: ``"beta_bernoulli"`` (exchangeable, Beta(alpha, beta) integrated
out) and ``"ising"`` (a :class:`~hubsgo_ppl.distributions.PairwiseMRF` whose couplings are
``strength`` times the human edge signs). Add your own with::

    @register_prior("sparse")
    class Sparse(Prior):
        def __init__(self, graph, rate=2.0): ...
        def distribution(self): ...   # a TorchDistribution with event_shape (N,)
"""

from __future__ import annotations

import math

import torch
from pyro.distributions import TorchDistribution
from torch.distributions import constraints

from ..distributions._provenance import retrack, to_batch_shape, untrack
from ..distributions.mrf import EXACT_LIMIT, PairwiseMRF
from ..graph import SubgoalGraph
from ._registry import build, make_register

__all__ = ["Prior", "PRIORS", "register_prior", "get_prior", "check_prior", "BernoulliSet", "BetaBernoulliSet"]

PRIORS: dict[str, type] = {}
register_prior = make_register(PRIORS, "prior", "distribution")


def get_prior(name: str, graph: SubgoalGraph, **params) -> "Prior":
    """Instantiate the prior registered as ``name`` for ``graph`` (unknown names list the registered ones)."""
    return build(PRIORS, "prior", name, graph, **params)


def check_prior(prior: "Prior") -> None:
    """A ``ValueError`` in one line where ``prior.distribution()`` cannot be the critic's p(w): none defined,
    not a distribution with event shape (N,) and no batch shape, or a log_prob of the empty and the full
    set that is not two finite numbers (every set q can sample needs a finite log p(w))."""
    n, name = prior.graph.n, prior.registered_name
    try:
        d = prior.distribution()
    except NotImplementedError:
        raise ValueError(f"prior {name!r} defines no distribution(); return a Pyro distribution over the "
                         f"{n} indicators, event shape ({n},)") from None
    except Exception as exc:     # a user's own class that fails: one line naming it, not a traceback
        raise ValueError(f"prior {name!r}: distribution() raised {type(exc).__name__}: {exc}") from None
    if not isinstance(d, torch.distributions.Distribution):
        raise ValueError(f"prior {name!r}: distribution() returned a {type(d).__name__}, not a Pyro distribution")
    if tuple(d.batch_shape) != () or tuple(d.event_shape) != (n,):
        raise ValueError(f"prior {name!r}: distribution() has batch shape {tuple(d.batch_shape)} and event shape "
                         f"{tuple(d.event_shape)}; it needs event shape ({n},), one indicator per sub-goal, and no "
                         "batch shape (e.g. dist.Bernoulli(...).to_event(1))")
    try:
        lp = d.log_prob(torch.stack([torch.zeros(n), torch.ones(n)]))
    except Exception as exc:
        raise ValueError(f"prior {name!r}: log_prob of the empty and the full set raised {type(exc).__name__}: "
                         f"{exc}") from None
    if tuple(lp.shape) != (2,) or not bool(torch.isfinite(lp).all()):
        raise ValueError(f"prior {name!r}: log_prob of the empty and the full set is {lp.tolist()}, not two finite "
                         "numbers; every set of sub-goals needs a finite log p(w)")


def _positive(kind: str, key: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{kind}: {key} must be a positive number, got {value!r}; e.g. {key}: 1.0")
    return value


class Prior:
    """Base class: holds the graph; subclasses build ``distribution()`` with event_shape (N,)."""

    registered_name = "?"

    def __init__(self, graph: SubgoalGraph):
        if not isinstance(graph, SubgoalGraph):
            raise TypeError(f"a prior needs a SubgoalGraph, got {type(graph).__name__}")
        self.graph = graph

    def distribution(self) -> TorchDistribution:
        raise NotImplementedError

    def params(self) -> dict[str, float]:
        return {}

    def natural_params(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """(theta (N,), coupling (E,)) on ``graph.edge_index`` when this prior is a pairwise MRF on the
        graph (so the guide can start equal to it, ``inference.init: prior``); None otherwise."""
        return None


@register_prior("bernoulli")
class BernoulliPrior(Prior):
    """Independent Bernoulli(p) per sub-goal; p = 0.5 is the paper's uniform prior."""

    def __init__(self, graph: SubgoalGraph, p: float = 0.5):
        super().__init__(graph)
        p = float(p)
        if not 0.0 < p < 1.0:
            raise ValueError(f"bernoulli prior: p must be in (0, 1), got {p!r}; p: 0.5 is the uniform prior")
        self.p = p

    def params(self):
        return {"p": self.p}

    def natural_params(self):
        theta = torch.full((self.graph.n,), math.log(self.p) - math.log1p(-self.p))
        return theta, torch.zeros(self.graph.num_edges)

    def distribution(self):
        return BernoulliSet(self.p, self.graph.n)


class BernoulliSet(TorchDistribution):
    """N independent Bernoulli(p) indicators as one event of shape (N,)."""

    support = constraints.independent(constraints.boolean, 1)
    arg_constraints = {}

    def __init__(self, p: float, n: int, generator: torch.Generator | None = None, validate_args=None, batch_shape=()):
        self.p = float(p)
        self.n = int(n)
        self.generator = generator if generator is not None else torch.Generator().manual_seed(0)
        self._log_p, self._log_not_p = math.log(self.p), math.log1p(-self.p)
        super().__init__(torch.Size(batch_shape), torch.Size([self.n]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        return type(self)(self.p, self.n, self.generator, self._validate_args, batch_shape)

    def log_prob(self, value):
        value, prov = untrack(value)
        if self._validate_args:
            self._validate_sample(value)
        k = value.sum(-1)
        lp = k * self._log_p + (self.n - k) * self._log_not_p
        return retrack(to_batch_shape(lp, self.batch_shape), prov)

    def sample(self, sample_shape=torch.Size()):
        shape = self._extended_shape(sample_shape)
        return (torch.rand(shape, generator=self.generator) < self.p).float()


class BetaBernoulliSet(TorchDistribution):
    """w_i | rho ~ Bernoulli(rho), rho ~ Beta(alpha, beta), with rho integrated out.

    p(w) = B(alpha + k, beta + N - k) / B(alpha, beta) with k = sum(w): exchangeable, so only the
    set size matters. Sampling draws k from the beta-binomial, then a uniformly random k-subset.
    """

    arg_constraints = {"alpha": constraints.positive, "beta": constraints.positive}
    support = constraints.independent(constraints.boolean, 1)

    def __init__(self, alpha: float, beta: float, n: int, generator: torch.Generator | None = None, validate_args=None, batch_shape=()):
        self.alpha = torch.as_tensor(float(alpha))
        self.beta = torch.as_tensor(float(beta))
        self.n = int(n)
        self.generator = generator if generator is not None else torch.Generator().manual_seed(0)
        super().__init__(torch.Size(batch_shape), torch.Size([self.n]), validate_args=validate_args)

    def expand(self, batch_shape, _instance=None):
        return type(self)(float(self.alpha), float(self.beta), self.n, self.generator, self._validate_args, batch_shape)

    def _log_beta(self, a, b):
        return torch.lgamma(a) + torch.lgamma(b) - torch.lgamma(a + b)

    def log_prob(self, value):
        value, prov = untrack(value)
        if self._validate_args:
            self._validate_sample(value)
        k = value.sum(-1)
        lp = self._log_beta(self.alpha + k, self.beta + self.n - k) - self._log_beta(self.alpha, self.beta)
        return retrack(to_batch_shape(lp, self.batch_shape), prov)

    def sample(self, sample_shape=torch.Size()):
        shape = self._extended_shape(sample_shape)
        k = torch.arange(self.n + 1, dtype=torch.float32)
        log_binom = torch.lgamma(torch.tensor(self.n + 1.0)) - torch.lgamma(k + 1) - torch.lgamma(self.n - k + 1)
        pmf = torch.exp(log_binom + self._log_beta(self.alpha + k, self.beta + self.n - k) - self._log_beta(self.alpha, self.beta))
        lead = shape[:-1]
        count = int(math.prod(lead))
        sizes = torch.multinomial(pmf, count, replacement=True, generator=self.generator).reshape(lead + (1,))
        ranks = torch.rand(shape, generator=self.generator).argsort(-1).argsort(-1)
        return (ranks < sizes).float()


@register_prior("beta_bernoulli")
class BetaBernoulliPrior(Prior):
    """Exchangeable prior that learns nothing about which sub-goals, only favours set sizes."""

    def __init__(self, graph: SubgoalGraph, alpha: float = 1.0, beta: float = 1.0):
        super().__init__(graph)
        self.alpha = _positive("beta_bernoulli prior", "alpha", alpha)
        self.beta = _positive("beta_bernoulli prior", "beta", beta)

    def params(self):
        return {"alpha": self.alpha, "beta": self.beta}

    def distribution(self):
        return BetaBernoulliSet(self.alpha, self.beta, self.graph.n)


@register_prior("ising")
class IsingPrior(Prior):
    """PairwiseMRF prior with theta = field and J_uv = strength * sign_uv (unknown signs give 0).

    Its log Z is exact for N <= 20; above, log_prob is unnormalised, which only shifts the ELBO by
    a constant (the prior has no learnable parameters).
    """

    def __init__(self, graph: SubgoalGraph, strength: float = 1.0, field: float = 0.0):
        super().__init__(graph)
        self.strength = float(strength)
        self.field = float(field)
        if not (math.isfinite(self.strength) and math.isfinite(self.field)):
            raise ValueError(f"ising prior: strength and field must be finite, got {strength!r}, {field!r}")
        if self.strength < 0:
            raise ValueError(f"ising prior: strength must be >= 0, got {strength!r}: it scales your edge signs, "
                             "so a negative one would turn every positive edge negative; give an edge the "
                             "sign negative instead")

    def params(self):
        return {"strength": self.strength, "field": self.field}

    def natural_params(self):
        return torch.full((self.graph.n,), self.field), self.strength * self.graph.edge_sign

    def distribution(self):
        theta, coupling = self.natural_params()
        return PairwiseMRF(
            theta,
            coupling,
            self.graph.edge_index,
            exact_max_n=EXACT_LIMIT,
        )
