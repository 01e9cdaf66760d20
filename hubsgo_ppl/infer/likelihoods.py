"""Likelihoods p(y_G | w) of the TD targets given the sub-goal indicators (Eq. 4).

A likelihood scores the residuals r = y_G(w) - Q(s, g) of a minibatch: ``distribution(loc=r)``
returns a distribution with batch shape ``r.shape`` that the critic's model observes at 0, i.e.
log p(y | w) = sum_b log f(0 | r_b) = sum_b log f(r_b | 0) for the symmetric families here.

``"gaussian"`` is Eq. 4: log N(r; 0, scale^2) = -r^2 / (2 scale^2) + const, which for scale = 1
is -L_G of Eq. 2. ``"student_t"`` and ``"laplace"`` are heavier-tailed alternatives that keep a few
huge early TD errors from dominating the critic.

``"outcome"`` scores other evidence (``evidence = "outcomes"``): the sets of sub-goals achieved on
the agent's recent successful episodes (``TDBatch.outcomes``, (E, N)), read as noisy copies of one
route w. Under Eq. 4 a sub-goal that is never the maximiser of Eq. 2 leaves the likelihood flat, so
the TD evidence cannot tell a route from any superset of it; an outcome names the sub-goals a
successful episode needed (docs/results.md, "Critic evidence and defaults").

Register your own with ``@register_likelihood("name")`` on a :class:`Likelihood` subclass: a TD
likelihood defines ``distribution(loc)``; an outcome likelihood sets ``evidence = "outcomes"`` and
defines ``log_likelihood(w, outcomes)``.
"""

from __future__ import annotations

import math

import pyro.distributions as dist
import torch

from ._registry import build, make_register

__all__ = ["Likelihood", "LIKELIHOODS", "register_likelihood", "get_likelihood", "check_likelihood"]

LIKELIHOODS: dict[str, type] = {}
register_likelihood = make_register(LIKELIHOODS, "likelihood", "log_likelihood")
EVIDENCE = ("td", "outcomes")


def get_likelihood(name: str, **params) -> "Likelihood":
    """Instantiate the likelihood registered as ``name`` (unknown names list the registered ones)."""
    return build(LIKELIHOODS, "likelihood", name, **params)


def check_likelihood(likelihood: "Likelihood", n: int) -> None:
    """A ``ValueError`` in one line where ``likelihood`` cannot score the critic's evidence for N = ``n``
    sub-goals: a TD likelihood's ``distribution(loc)`` must exist, have ``loc``'s shape as its batch shape
    and no event shape, and give finite log-densities of 0; an outcome likelihood's ``log_likelihood`` must
    give one finite number per mask."""
    name = likelihood.registered_name
    if likelihood.evidence not in EVIDENCE:
        raise ValueError(f"likelihood {name!r}: evidence is {likelihood.evidence!r}; use one of: {', '.join(EVIDENCE)}")
    if likelihood.evidence == "outcomes":
        masks = torch.stack([torch.zeros(n), torch.ones(n)])
        try:
            ll = likelihood.log_likelihood(masks, torch.ones(1, n))
        except Exception as exc:     # a user's own class that fails: one line naming it, not a traceback
            raise ValueError(f"likelihood {name!r}: log_likelihood(masks (2, {n}), outcomes (1, {n})) raised "
                             f"{type(exc).__name__}: {exc}") from None
        if not isinstance(ll, torch.Tensor) or tuple(ll.shape) != (2,) or not bool(torch.isfinite(ll).all()):
            got = tuple(ll.shape) if isinstance(ll, torch.Tensor) else type(ll).__name__
            raise ValueError(f"likelihood {name!r}: log_likelihood(masks (2, {n}), outcomes (1, {n})) gave {got}, not "
                             "two finite numbers, one per mask")
        return
    loc = torch.tensor([[0.0, 0.5, -2.0], [1.0, -0.5, 3.0]])
    try:
        d = likelihood.distribution(loc)
    except NotImplementedError:
        raise ValueError(f"likelihood {name!r} defines no distribution(loc); return a Pyro distribution of the "
                         "residuals with loc's shape as its batch shape") from None
    except Exception as exc:
        raise ValueError(f"likelihood {name!r}: distribution(loc) raised {type(exc).__name__}: {exc}") from None
    if not isinstance(d, torch.distributions.Distribution):
        raise ValueError(f"likelihood {name!r}: distribution(loc) returned a {type(d).__name__}, not a Pyro "
                         "distribution")
    if tuple(d.batch_shape) != tuple(loc.shape) or tuple(d.event_shape) != ():
        raise ValueError(f"likelihood {name!r}: distribution(loc) for loc of shape {tuple(loc.shape)} has batch "
                         f"shape {tuple(d.batch_shape)} and event shape {tuple(d.event_shape)}; it needs loc's "
                         "shape as its batch shape and no event shape, one density per residual")
    try:
        lp = d.log_prob(torch.zeros(loc.shape))
    except Exception as exc:
        raise ValueError(f"likelihood {name!r}: log_prob(0) raised {type(exc).__name__}: {exc}") from None
    if not bool(torch.isfinite(lp).all()):
        raise ValueError(f"likelihood {name!r}: log_prob(0) of residuals {loc.flatten().tolist()} is not finite "
                         f"({lp.flatten().tolist()}); the critic needs a finite density for every residual")


def _positive(kind: str, key: str, value: float, example: float = 1.0) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{kind} likelihood: {key} must be a number, got {value!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{kind} likelihood: {key} must be > 0, got {value!r}; e.g. {key}: {example}")
    return value


class Likelihood:
    """Base class. ``evidence`` says what the likelihood scores:

    - ``"td"``: the TD residuals of Eq. 2; subclasses define ``distribution(loc)`` with batch shape
      ``loc.shape``, observed at 0;
    - ``"outcomes"``: the achieved sets of recent successful episodes; subclasses define
      ``log_likelihood(w, outcomes)``.
    """

    registered_name = "?"
    evidence = "td"

    def distribution(self, loc: torch.Tensor):
        raise NotImplementedError(f"{type(self).__name__} scores {self.evidence!r} evidence, not TD residuals")

    def log_likelihood(self, w: torch.Tensor, *inputs: torch.Tensor) -> torch.Tensor:
        """log p(evidence | w) for masks ``w`` (..., N) -> (...,). For TD likelihoods ``inputs`` are
        :meth:`TDBatch.tensors`; the sum of ``distribution(r).log_prob(0)`` over the minibatch."""
        from .tdbatch import td_residuals

        r = td_residuals(w, *inputs)
        return self.distribution(r).log_prob(torch.zeros(())).sum(-1)

    def params(self) -> dict[str, float]:
        return {}

    def settled_scale(self) -> float:
        """The factor on this likelihood's log-likelihood in the critic G* is read from once the agent
        has settled (its recent training episodes succeed reliably; the loop's ``settle_at``, a batch's
        ``TDBatch.settled``): 1 here."""
        return 1.0


@register_likelihood("gaussian")
class GaussianLikelihood(Likelihood):
    """Eq. 4: y_G = Q(s, g) + eps, eps ~ N(0, scale^2)."""

    def __init__(self, scale: float = 1.0):
        self.scale = _positive("gaussian", "scale", scale)

    def params(self):
        return {"scale": self.scale}

    def distribution(self, loc):
        return dist.Normal(loc, self.scale)


@register_likelihood("student_t")
class StudentTLikelihood(Likelihood):
    """Student-t errors with ``df`` degrees of freedom."""

    def __init__(self, df: float = 3.0, scale: float = 1.0):
        self.df = _positive("student_t", "df", df)
        self.scale = _positive("student_t", "scale", scale)

    def params(self):
        return {"df": self.df, "scale": self.scale}

    def distribution(self, loc):
        return dist.StudentT(self.df, loc, self.scale)


@register_likelihood("laplace")
class LaplaceLikelihood(Likelihood):
    """Laplace errors: an absolute-error TD loss."""

    def __init__(self, scale: float = 1.0):
        self.scale = _positive("laplace", "scale", scale)

    def params(self):
        return {"scale": self.scale}

    def distribution(self, loc):
        return dist.Laplace(loc, self.scale)


@register_likelihood("outcome")
class OutcomeLikelihood(Likelihood):
    """Evidence from outcomes: each recent successful episode's achieved set ``a_e`` (E, N) is a noisy
    copy of one route, each indicator flipped with probability ``flip``; the route is one of them,
    and the evidence is tempered by ``power``::

        log p(a_1..a_E | w) = power * log( 1/E sum_e prod_i flip^[a_ei != w_i] (1 - flip)^[a_ei == w_i] )

    Once the agent has settled (the loop's ``settle_at``: its recent training episodes succeed
    reliably), G* is read from a copy of the critic refitted at the power ``max(power, settled_power)``
    (``SubgoalCritic.settled``): the successes of an agent that has learned the task are cleaner
    evidence than its first, wandering ones. The critic that chooses Ĝt keeps reading them at ``power``.

    A mixture over episodes, not a product: the posterior's mode is the most frequent successful set
    (smoothed by ``flip``), so two routes seen equally often give two modes rather than their union,
    and the evidence does not harden as episodes accumulate. Each sub-goal that ``w`` sets differently
    from an episode costs ``power * log((1 - flip) / flip)`` nats: 0.97 at the defaults (0.25, 0.02).

    ``power`` sets how far the agent's successes can overrule the human's prior. At 0.25 a mismatch
    costs less than the shipped specs' Ising field of -2, so a sub-goal needs a positive edge to enter
    G*, and the evidence chooses among the routes the edges allow; the sub-goals that a wandering early
    success crossed by chance cannot lock themselves into Ĝt. At 1 the evidence also brings in a
    sub-goal every success needs that the spec left unlinked, and undoes a wrong positive edge, but on
    mazes with many candidate cells the first successes' cells then stay in Ĝt, and learning slows
    (docs/results.md, "How strongly the successes speak").

    ``settled_power`` 0.4 makes a mismatch cost 1.56 nats: more than the +1 that one positive edge to
    the route gives a sub-goal against the field of -2 (so a linked sub-goal that no recent success
    achieved, such as the door of the route not taken, leaves G*), and less than the field's 2 (so a
    sub-goal without a positive edge still cannot enter, however often the successes pass it).
    """

    evidence = "outcomes"

    def __init__(self, flip: float = 0.02, power: float = 0.25, settled_power: float = 0.4):
        flip = _positive("outcome", "flip", flip, example=0.02)
        if not flip < 0.5:
            raise ValueError(f"outcome likelihood: flip must be < 0.5, got {flip!r}; e.g. flip: 0.02")
        self.flip = flip
        self.power = _positive("outcome", "power", power)
        self.settled_power = _positive("outcome", "settled_power", settled_power)

    def params(self):
        return {"flip": self.flip, "power": self.power, "settled_power": self.settled_power}

    def settled_scale(self) -> float:
        return max(self.power, self.settled_power) / self.power

    @property
    def mismatch_nats(self) -> float:
        """What each sub-goal that ``w`` sets differently from an episode costs: ``power * log((1 - flip)
        / flip)`` nats, the most the evidence can pull one sub-goal against the prior."""
        return self.power * (math.log1p(-self.flip) - math.log(self.flip))

    def log_likelihood(self, w: torch.Tensor, outcomes: torch.Tensor) -> torch.Tensor:
        if outcomes.dim() != 2 or outcomes.shape[0] == 0 or outcomes.shape[1] != w.shape[-1]:
            raise ValueError(f"outcomes must have shape (E >= 1, {w.shape[-1]}), got {tuple(outcomes.shape)}")
        mismatch = (w.unsqueeze(-2) - outcomes).abs().sum(-1)                     # (..., E)
        n = w.shape[-1]
        per_episode = mismatch * math.log(self.flip) + (n - mismatch) * math.log1p(-self.flip)
        return (torch.logsumexp(per_episode, -1) - math.log(outcomes.shape[0])) * self.power
