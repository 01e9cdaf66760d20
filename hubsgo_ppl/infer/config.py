"""The critic's inference settings: :class:`InferenceSpec`, the ``inference:`` section of a model spec.

One pydantic model serves both faces: :class:`hubsgo_ppl.specs.ModelSpec` nests it (its errors name
the spec file and the key), and :class:`~hubsgo_ppl.infer.critic.SubgoalCritic` takes it as its
``config``. :class:`InferenceConfig` is the same model built from keyword arguments: a bad value
raises a one-line ``ValueError`` naming the field, e.g.
``InferenceConfig.lr = -1.0: input should be greater than 0 (default 0.05)``.

The module needs pydantic only, so that importing :mod:`hubsgo_ppl.specs` stays free of torch. The
kernel names and the enumeration limit are therefore restated here; tests/infer/test_config.py checks
them against :data:`~hubsgo_ppl.distributions.mh_kernels.KERNELS` and
:data:`~hubsgo_ppl.distributions.mrf.EXACT_LIMIT`.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from ..validation import format_validation_error, no_bool_as_number

__all__ = ["InferenceSpec", "InferenceConfig", "MAX_EXACT_N"]

MAX_EXACT_N = 20  # distributions.mrf.EXACT_LIMIT: the largest N whose 2^N states are enumerated


class InferenceSpec(BaseModel):
    """Settings of the critic's inference (paper defaults: burn-in 32, 64 samples per update)."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True)
    _no_bool_as_number = field_validator("*", mode="before")(classmethod(no_bool_as_number))

    lr: float = Field(0.05, gt=0, le=10.0, allow_inf_nan=False, description="Adam step size for theta and J")
    burn_in: int = Field(32, ge=0, le=1_000_000, description="MH sweeps per update, from the chains' last state")
    num_samples: int = Field(
        64, ge=2, le=65_536, description="S: MH chains = vectorised ELBO particles per update (the leave-one-out score needs 2)")
    kernel: Literal["single_site", "block"] = Field(
        "single_site", description="MH kernel: chromatic single-site flip sweeps, or block flips")
    baseline_beta: float = Field(
        0.9, ge=0, lt=1, description="decay of TraceGraph_ELBO's average baseline (variance reduction)")
    init_scale: float = Field(
        1.0, ge=0, le=1e9, allow_inf_nan=False,
        description="initial coupling = init_scale * human edge sign (init: edges; a sign's direction is the edge's, "
                    "so the scale is 0 or more); the couplings are float32")
    init: Literal["edges", "prior"] = Field(
        "edges", description="where q starts: theta = 0, J = init_scale * edge sign ('edges'), or q = p(w) "
                             "('prior': KL = 0 before any data; needs a prior the guide's family holds, e.g. "
                             "bernoulli or ising)")
    exact_max_n: int = Field(16, ge=0, le=MAX_EXACT_N, description="exact log Z for N <= this; leave-one-out above")
    pyro_validation: Literal["first", "always", "never"] = Field(
        "first", description="Pyro's validation (distribution arguments, site shapes, NaN/inf warnings) on the "
                             "first update only, on every update, or never: it costs ~20% of an update, and a "
                             "custom prior or likelihood that passes it once passes it every time")
    jit: bool = Field(
        True, strict=True, description="compile the TraceGraph_ELBO step of TDBatch updates with torch.jit.trace "
                                       "(the same numbers, an update ~3.4x faster); callables always run eagerly")


class InferenceConfig(InferenceSpec):
    """:class:`InferenceSpec` built from keyword arguments, as the critic's callers do: the same fields,
    defaults and checks, with a bad value (on construction or assignment) raised as a one-line
    ``ValueError`` naming the field. (:class:`InferenceSpec` keeps pydantic's own errors: a model spec
    nests it, and :func:`hubsgo_ppl.specs.validate_spec` names the file and the key from them.)"""

    def __init__(self, **values: Any):
        try:
            super().__init__(**values)
        except ValidationError as err:
            raise ValueError(_one_line(type(self), err)) from None

    def __setattr__(self, name: str, value: Any) -> None:
        try:
            super().__setattr__(name, value)
        except ValidationError as err:
            raise ValueError(_one_line(type(self), err)) from None


def _one_line(cls: type[InferenceSpec], err: ValidationError) -> str:
    """``Class.field = value: problem (default ...)`` per problem, on one line."""
    return format_validation_error(cls.__name__, err, model=cls, sep="; ")
