"""Likelihoods p(y_G | w) of the TD targets given the sub-goal indicators (Eq. 4).

A likelihood scores the residuals r = y_G(w) - Q(s, g) of a minibatch: ``distribution(loc=r)``
returns a distribution with batch shape ``r.shape`` that the critic's model observes at 0, i.e.
log p(y | w) = sum_b log f(0 | r_b) = sum_b log f(r_b | 0) for the symmetric families here.

``"gaussian"`` (default) is Eq. 4: log N(r; 0, scale^2) = -r^2 / (2 scale^2) + const, which for
scale = 1 is -L_G of Eq. 2. ``"student_t"`` and ``"laplace"`` are heavier-tailed alternatives that
keep a few huge early TD errors from dominating the critic. Register your own with
``@register_likelihood("name")`` on a :class:`Likelihood` subclass.
"""

from __future__ import annotations

import math

import pyro.distributions as dist
import torch

from ._registry import build, make_register

__all__ = ["Likelihood", "LIKELIHOODS", "register_likelihood", "get_likelihood"]

LIKELIHOODS: dict[str, type] = {}
register_likelihood = make_register(LIKELIHOODS, "likelihood", "distribution")


def get_likelihood(name: str, **params) -> "Likelihood":
    """Instantiate the likelihood registered as ``name`` (unknown names list the registered ones)."""
    return build(LIKELIHOODS, "likelihood", name, **params)


def _positive(kind: str, key: str, value: float) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{kind} likelihood: {key} must be a number, got {value!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{kind} likelihood: {key} must be > 0, got {value!r}; e.g. {key}: 1.0")
    return value


class Likelihood:
    """Base class: ``distribution(loc)`` with batch shape ``loc.shape``."""

    registered_name = "?"

    def distribution(self, loc: torch.Tensor):
        raise NotImplementedError

    def params(self) -> dict[str, float]:
        return {}


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
