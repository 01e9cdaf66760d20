"""The HUBS-GO sub-goal critic: black-box VI of q(w; lambda) with TraceGraph_ELBO (Sec. 3.3-3.4).

Model (Eq. 3-4)::

    w ~ p(w)                                    prior over indicator vectors (default uniform)
    0 ~ f(. | r(w)),  r(w) = y_G(w) - Q(s, g)   residuals of the minibatch, likelihood f (Eq. 4)

or, for a likelihood with ``evidence = "outcomes"``, the factor log p(outcomes | w) of the achieved
sets of recent successful episodes (``TDBatch.outcomes``) in place of the residuals' term.

Guide: the pairwise MRF q(w; lambda) of Eq. 1 whose ``theta`` (unary) and ``coupling`` (pairwise)
are ``pyro.param`` s, initialised to 0 and ``init_scale * edge sign``, or to the prior itself with
``init="prior"``. Its sample site returns w drawn with our MH kernels from persistent chains (S
chains, ``burn_in`` sweeps from their last state per update).
``TraceGraph_ELBO(num_particles=S, vectorize_particles=True)`` then gives the score-function gradient
of Eq. 5, L(lambda) = E_q[L_G] + KL(q || p), with a decaying-average baseline; one
:meth:`SubgoalCritic.update` is lines 9-11 of Algorithm 1.

One model and one guide serve every update, eager or compiled (``inference.jit``, the
:class:`CompiledTraceGraph_ELBO`): they take every tensor as an argument, as ``torch.jit.trace``
needs, and the MH draw is made before the call (:meth:`SubgoalCritic._draw`; our kernels use a
``torch.Generator``, which a trace cannot carry), so the guide's site returns those draws. The evidence
is a :class:`TDBatch`'s TD tensors, its outcomes (likelihoods with ``evidence = "outcomes"``), or a
residual callable, which only the eager ELBO runs.

The parameters live in the critic's own Pyro param-store state (entered with
``ParamStoreDict.scope`` on every call), so critics never see each other's parameters. The critic
does no IO.

Residual functions must be built from torch ops on w (e.g. ``torch.where`` masking, as in
:meth:`TDBatch.residuals`): TraceGraph_ELBO finds the costs that depend on w by provenance tracking,
and Python control flow or ``.item()`` on w would silently drop the likelihood from the gradient.
:meth:`SubgoalCritic.update` refuses such residuals.

Learning budget on the synthetic KeyDoor problem of ``tests/infer/test_critic.py`` (mass > 0.8 on
the two correct pair configurations, lr 0.05, 64 samples, burn-in 32), measured by
benchmarks/critic.py over seeds 0-2: specific 40-50 updates, fully_connected 30-40, independent
100-160 (see docs/benchmarks.md, "Critic").
"""

from __future__ import annotations

import copy
import math
from typing import Any, Callable

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.infer import TraceGraph_ELBO
from pyro.ops.provenance import get_provenance
from torch.distributions import constraints

from ..distributions._provenance import WithProvenance, untrack
from ..distributions.mh_kernels import ChromaticScan, mh_steps
from ..distributions.mrf import PairwiseMRF
from ..graph import SubgoalGraph
from .compiled_elbo import CompiledTraceGraph_ELBO
from .config import InferenceConfig, InferenceSpec
from .likelihoods import get_likelihood
from .priors import get_prior
from .readout import CriticReadout, unique_rows
from .tdbatch import TDBatch, td_residuals

__all__ = ["InferenceConfig", "InferenceSpec", "TDBatch", "SubgoalCritic", "CompiledTraceGraph_ELBO", "td_residuals",
           "unique_rows"]

_SIGN_NAMES = {"positive": 1, "negative": -1, "unknown": 0}
_ENTROPY_CLAMP = 1e-6  # per-site sample means are clamped to [this, 1 - this] in the entropy bound


class SubgoalCritic(CriticReadout):
    """The Bayesian sub-goal critic q(w; lambda) of Sec. 3.3, trained by :meth:`update` (Alg. 1, 9-11).

    ``config`` is an :class:`InferenceSpec` (``InferenceConfig(...)`` builds one from keywords); the
    readers (:meth:`filtered_set`, :meth:`ranking`, :meth:`marginals`, ...) come from
    :class:`~hubsgo_ppl.infer.readout.CriticReadout`.

    >>> from hubsgo_ppl.graph import SubgoalGraph
    >>> g = SubgoalGraph(["key", "door", "goal"], [("key", "door", 1)])
    >>> critic = SubgoalCritic(g, seed=0)
    >>> diag = critic.update(lambda w: (1.0 - w[..., 2:3]) * 2.0)   # residual 2 unless "goal" kept
    >>> sorted(k for k in diag)[:3]
    ['elbo', 'entropy', 'entropy_is_exact']
    """

    def __init__(
        self,
        graph: SubgoalGraph,
        prior: str = "bernoulli",
        prior_params: dict | None = None,
        likelihood: str = "gaussian",
        likelihood_params: dict | None = None,
        config: InferenceSpec | None = None,
        seed: int = 0,
    ):
        if not isinstance(graph, SubgoalGraph):
            raise TypeError(f"graph must be a SubgoalGraph, got {type(graph).__name__}")
        if config is not None and not isinstance(config, InferenceSpec):
            raise TypeError(f"config must be an InferenceConfig (or InferenceSpec), got {type(config).__name__}")
        self.graph = graph
        self.names = list(graph.names)
        self.n = graph.n
        self.config = config if config is not None else InferenceConfig()
        self.prior = get_prior(prior, graph, **(prior_params or {}))
        self.likelihood = get_likelihood(likelihood, **(likelihood_params or {}))
        self.seed = int(seed)
        cfg = self.config
        self._edge_index = graph.edge_index
        self._prior_dist = self.prior.distribution()
        self._generator = torch.Generator().manual_seed(self.seed)
        theta, coupling = torch.zeros(self.n), cfg.init_scale * graph.edge_sign
        if cfg.init == "prior":
            natural = self.prior.natural_params()
            if natural is None:
                raise ValueError(
                    f"inference.init = 'prior' needs a prior that the guide (a pairwise MRF on this graph) can "
                    f"represent, such as bernoulli or ising; {prior!r} is not one. Use init: edges")
            theta, coupling = natural
        self._theta = theta.detach().clone().float().requires_grad_(True)
        self._coupling = coupling.detach().clone().float().requires_grad_(True)
        self._param_state = {
            "params": {"theta": self._theta, "coupling": self._coupling},
            "constraints": {"theta": constraints.real, "coupling": constraints.real},
        }
        self._optim = torch.optim.Adam([self._theta, self._coupling], lr=cfg.lr)
        self._elbo = TraceGraph_ELBO(num_particles=cfg.num_samples, vectorize_particles=True, max_plate_nesting=0)
        self._baseline = {"use_decaying_avg_baseline": True, "baseline_beta": cfg.baseline_beta}
        self._site: tuple = ()  # (guide distribution, sample) of the last guide call, eager or compiled
        self._compiled_elbo = CompiledTraceGraph_ELBO(
            self._model, self._guide, baseline_sites=("w",), extras=self._site_stats,
            num_particles=cfg.num_samples, vectorize_particles=True, max_plate_nesting=0,
        ) if cfg.jit else None
        self._chains = torch.randint(0, 2, (cfg.num_samples, self.n), generator=self._generator).float()
        self._scan = ChromaticScan(self._edge_index, self.n) if cfg.kernel == "single_site" else None
        self._last_samples: torch.Tensor | None = None
        self.num_updates = 0

    @classmethod
    def from_spec(cls, spec: Any, seed: int = 0) -> "SubgoalCritic":
        """Build a critic from a validated :class:`hubsgo_ppl.specs.ModelSpec` (its sub-goals, edges,
        graph preset, prior, likelihood and inference settings)."""
        graph = SubgoalGraph(spec.subgoals, [(u, v, _SIGN_NAMES[s]) for u, v, s in spec.edges]).preset(spec.graph)
        prior = spec.prior.model_dump()
        likelihood = spec.likelihood.model_dump()
        return cls(
            graph,
            prior=prior.pop("name"),
            prior_params=prior,
            likelihood=likelihood.pop("name"),
            likelihood_params=likelihood,
            config=spec.inference.model_copy(),
            seed=seed,
        )

    # -- Pyro model and guide (see the module docstring) ---------------------------------------

    def _model(self, draws: torch.Tensor, *evidence: torch.Tensor, weight: float = 1.0,
               residual_fn: Callable[[torch.Tensor], torch.Tensor] | None = None) -> None:
        """p(w) and the likelihood of ``evidence``: :meth:`TDBatch.tensors`, or ``(outcomes,)`` for an
        outcome likelihood, or nothing with a ``residual_fn`` (eager only)."""
        w = pyro.sample("w", self._prior_dist)
        if self.likelihood.evidence == "outcomes":
            plain, prov = untrack(w)       # log_likelihood(w, outcomes) as a factor that depends on w
            ll = self.likelihood.log_likelihood(plain, evidence[0])
            with pyro.poutine.scale(scale=weight):
                pyro.sample("outcomes", WithProvenance(dist.Unit(ll), prov), obs=torch.zeros(ll.shape + (0,)))
            return
        if residual_fn is None:
            r = td_residuals(w, *evidence)
        else:
            r = residual_fn(w)
            self._check_residuals(r, w)
        r, prov = untrack(r)
        lik = WithProvenance(self.likelihood.distribution(r).to_event(1), prov)
        with pyro.poutine.scale(scale=weight):
            pyro.sample("td", lik, obs=torch.zeros(r.shape))

    def _guide(self, draws: torch.Tensor, *evidence: torch.Tensor, weight: float = 1.0,
               residual_fn: Callable | None = None) -> None:
        """q(w; lambda), its site returning ``draws`` (the MH draw of :meth:`_draw`, made before the call)."""
        d = PairwiseMRF(pyro.param("theta"), pyro.param("coupling"), self._edge_index, burn_in=0, init=draws,
                        generator=self._generator, exact_max_n=self.config.exact_max_n, validate_args=False)
        w = pyro.sample("w", d, infer={"baseline": self._baseline})
        self._site = (d, w)

    def _site_stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The update's diagnostics from the last guide call (outputs of the compiled step): mean log q(w)
        of the samples under q before the step (for the entropy; Pyro's own log_prob of them is cached)
        and the mean set size."""
        d, w = self._site
        return d.log_prob(w).mean(), w.sum(-1).mean()

    def _draw(self) -> torch.Tensor:
        """The guide's sample: ``burn_in`` MH sweeps from the persistent chains, (S, N)."""
        cfg = self.config
        theta, coupling = self._theta.detach(), self._coupling.detach()
        if self._scan is not None and cfg.burn_in > 0:  # what mh_steps runs, minus its per-call set-up
            return self._scan(self._chains, theta, coupling, self._generator, cfg.burn_in)
        with torch.no_grad():
            return mh_steps(self._chains.to(theta.dtype), theta, coupling, self._edge_index, self._generator,
                            cfg.burn_in, cfg.kernel)

    def _check_residuals(self, r, w) -> None:
        if not isinstance(r, torch.Tensor):
            raise TypeError(f"residual_fn must return a tensor (..., B), got {type(r).__name__}")
        if r.dim() != w.dim() or r.shape[:-1] != w.shape[:-1]:
            raise ValueError(
                f"residual_fn returned shape {tuple(r.shape)} for masks of shape {tuple(w.shape)}; "
                f"it must return (..., B) with the masks' leading dims {tuple(w.shape[:-1])}"
            )
        if "w" not in get_provenance(r):
            raise ValueError(
                "residual_fn's output does not depend on w through torch ops; build it with tensor "
                "masking (torch.where) instead of Python control flow or .item() on w, otherwise the "
                "likelihood silently drops out of the gradient"
            )
        if not bool(torch.isfinite(untrack(r)[0]).all()):
            raise FloatingPointError("residual_fn returned NaN or inf residuals; check the Q-values and rewards")

    # -- training ----------------------------------------------------------------------------

    def _evidence(self, data) -> tuple[tuple[torch.Tensor, ...], float, Callable | None]:
        """``(evidence tensors, weight, residual_fn)`` of what :meth:`update` was given: a TDBatch's TD
        tensors at its ``weight``, its outcomes (for an outcome likelihood) at weight 1 (at the
        likelihood's ``settled_scale()`` where the batch says ``settled``: :meth:`settled`), or a residual
        callable with no tensors at weight 1. The weight is that of a pool of TD minibatches
        (:meth:`TDBatch.cat`); the outcomes are the whole window of recent successes, whatever the pool,
        so they count once: weighing them by 1/K would temper the evidence by how often the critic
        updates."""
        if isinstance(data, TDBatch):
            if data.n != self.n:
                raise ValueError(f"TDBatch has {data.n} sub-goal columns but the critic has N = {self.n}")
            if self.likelihood.evidence == "outcomes":
                if data.outcomes is None or data.outcomes.shape[0] == 0:
                    raise ValueError(f"the {self.likelihood.registered_name!r} likelihood scores outcomes, and "
                                     "this TDBatch has none; attach the achieved sets of successful episodes")
                return (data.outcomes,), self.likelihood.settled_scale() if data.settled else 1.0, None
            return data.tensors(), data.weight, None
        if self.likelihood.evidence == "outcomes":
            raise TypeError(f"the {self.likelihood.registered_name!r} likelihood scores outcomes: pass a TDBatch "
                            "with `outcomes`, not a residual function")
        if not callable(data):
            raise TypeError(f"update() takes a TDBatch or a callable residual_fn, got {type(data).__name__}")
        return (), 1.0, data

    def _loss_and_grads(self, data) -> float:
        evidence, weight, residual_fn = self._evidence(data)
        self._theta.grad = None
        self._coupling.grad = None
        validate = self.config.pyro_validation == "always" or (
            self.config.pyro_validation == "first" and self.num_updates == 0)
        draws = self._draw()
        params = self._param_state["params"]
        # the step updates the baseline in place; a step that fails puts back this copy
        baseline = {k: v.detach().clone() for k, v in params.items() if k.startswith("__baseline")}
        try:
            loss = self._elbo_step(draws, evidence, weight, residual_fn, validate)
        except Exception:
            self._restore_baseline(baseline)
            raise
        self._chains = self._last_samples = draws
        return loss

    def _restore_baseline(self, baseline: dict) -> None:
        """Put back the decaying-average baseline of before a step that failed: a non-finite cost folded
        into it would make every later update's gradient non-finite."""
        params, cons = self._param_state["params"], self._param_state["constraints"]
        for k in [k for k in params if k.startswith("__baseline") and k not in baseline]:
            del params[k]
            cons.pop(k, None)
        params.update(baseline)

    def _elbo_step(self, draws, evidence, weight, residual_fn, validate) -> float:
        if self._compiled_elbo is not None and residual_fn is None and not validate:
            loss = self._compiled_elbo.step(self._param_state, draws, *evidence, weight=weight)
            self._step_stats = self._compiled_elbo.extra_values
        else:
            with pyro.get_param_store().scope(state=self._param_state), pyro.validation_enabled(validate):
                loss = self._elbo.loss_and_grads(self._model, self._guide, draws, *evidence, weight=weight,
                                                 residual_fn=residual_fn)
            with torch.no_grad():
                self._step_stats = tuple(x.detach() for x in self._site_stats())
        if not math.isfinite(loss):
            raise FloatingPointError(
                f"critic loss is {loss}: the likelihood of some sampled set is non-finite; "
                "check the residual scale (likelihood scale) and the Q-values"
            )
        self._grad_sq = []
        for name, p in (("theta", self._theta), ("coupling", self._coupling)):
            if p.grad is None:
                continue
            sq = float((p.grad**2).sum())
            # sq is finite unless a gradient is non-finite (or so large that its square overflows)
            if not math.isfinite(sq) and not bool(torch.isfinite(p.grad).all()):
                raise FloatingPointError(f"non-finite gradient for the critic's {name}; lower the learning rate or the residual scale")
            self._grad_sq.append(sq)
        return loss

    def estimate_gradient(self, residual_fn) -> dict[str, torch.Tensor | float]:
        """One Eq. 5 gradient estimate without stepping: ``{"loss", "theta", "coupling"}`` (chains advance)."""
        loss = self._loss_and_grads(residual_fn)
        grads = {
            name: (p.grad.detach().clone() if p.grad is not None else torch.zeros_like(p))
            for name, p in (("theta", self._theta), ("coupling", self._coupling))
        }
        return {"loss": loss, **grads}

    def update(self, residual_fn: Callable[[torch.Tensor], torch.Tensor] | TDBatch) -> dict[str, float]:
        """One critic step, Algorithm 1 lines 9-11: draw S samples, estimate Eq. 5, take an Adam step.

        ``residual_fn`` maps masks (S, N) to residuals (S, B), or is a :class:`TDBatch`.
        Returns floats: ``loss`` (-ELBO estimate, i.e. E[L_G] + KL up to constants; above
        exact_max_n it lacks the -log Z term), ``elbo``, ``grad_norm``, ``entropy`` (Monte Carlo
        estimate of H[q] when exact, else the upper bound sum of per-site entropies; see
        ``entropy_is_exact``), ``mean_set_size``, ``unique_configs``, ``theta_abs_max``.
        """
        loss = self._loss_and_grads(residual_fn)
        with torch.no_grad():
            grad_sq = sum(self._grad_sq)
            samples = self._last_samples
            mean_log_q, mean_set_size = self._step_stats  # under q before the step: the samples' distribution
            if self.n <= self.config.exact_max_n:
                entropy, exact = -float(mean_log_q), 1.0
            else:
                m = samples.mean(0).clamp(_ENTROPY_CLAMP, 1 - _ENTROPY_CLAMP)
                entropy, exact = float(-(m * m.log() + (1 - m) * (1 - m).log()).sum()), 0.0
            self._optim.step()
            theta, coupling = self._theta.detach().numpy(), self._coupling.detach().numpy()   # views
            if not (np.isfinite(theta).all() and np.isfinite(coupling).all()):
                raise FloatingPointError("critic parameters became non-finite after the step; lower the learning rate (inference.lr)")
            theta_abs_max = float(np.abs(theta).max())
            self.num_updates += 1
            _, configs, _ = self._sample_counts()
            return {
                "loss": loss,
                "elbo": -loss,
                "grad_norm": math.sqrt(grad_sq),
                "entropy": entropy,
                "entropy_is_exact": exact,
                "mean_set_size": float(mean_set_size),
                "unique_configs": float(configs.shape[0]),
                "theta_abs_max": theta_abs_max,
            }

    def settled(self, outcomes: torch.Tensor, steps: int) -> "SubgoalCritic":
        """A copy of this critic after ``steps`` updates on ``outcomes`` (E, N) read at the likelihood's
        settled power (:meth:`~hubsgo_ppl.infer.likelihoods.Likelihood.settled_scale`): the posterior
        that the successes of a settled agent give. This critic, its chains and its RNG are unchanged.
        A likelihood without a settled power (scale 1), or no outcomes, gives this critic itself."""
        if self.likelihood.settled_scale() == 1.0 or outcomes is None or outcomes.shape[0] == 0:
            return self
        twin = SubgoalCritic(self.graph, prior=self.prior.registered_name, prior_params=self.prior.params(),
                             likelihood=self.likelihood.registered_name, likelihood_params=self.likelihood.params(),
                             config=self.config, seed=self.seed)
        twin.load_state_dict(self.state_dict())
        batch = TDBatch(q_taken=torch.zeros(0), q_next=torch.zeros(0, self.n), reward=torch.zeros(0),
                        discount=torch.zeros(0), outcomes=outcomes, settled=True)
        for _ in range(int(steps)):
            twin.update(batch)
        return twin

    # -- checkpoints -------------------------------------------------------------------------

    def state_dict(self) -> dict:
        """Parameters, optimiser, chains, baseline and RNG state, plus plain config (no callables)."""
        baseline = {k: v.detach().clone() for k, v in self._param_state["params"].items() if k.startswith("__baseline")}
        return {
            "names": list(self.names),
            "edges": [list(e) for e in self.graph.edges],
            "config": self.config.model_dump(),
            "theta": self._theta.detach().clone(),
            "coupling": self._coupling.detach().clone(),
            "optimizer": copy.deepcopy(self._optim.state_dict()),
            "chains": self._chains.clone(),
            "last_samples": None if self._last_samples is None else self._last_samples.clone(),
            "baseline": baseline,
            "rng": self._generator.get_state(),
            "num_updates": self.num_updates,
        }

    def load_state_dict(self, state: dict) -> None:
        """Restore :meth:`state_dict` output; the graph must match this critic's."""
        if state.get("names") != self.names or [tuple(e) for e in state.get("edges", [])] != self.graph.edges:
            raise ValueError("state_dict was saved for a different sub-goal graph (names or edges differ); build the critic from the same spec")
        with torch.no_grad():
            self._theta.copy_(state["theta"])
            self._coupling.copy_(state["coupling"])
        self._optim.load_state_dict(copy.deepcopy(state["optimizer"]))
        self._chains = state["chains"].clone()
        self._last_samples = None if state["last_samples"] is None else state["last_samples"].clone()
        params, cons = self._param_state["params"], self._param_state["constraints"]
        for k in [k for k in params if k.startswith("__baseline")]:
            del params[k]
            cons.pop(k, None)
        for k, v in state["baseline"].items():
            params[k] = v.clone()
            cons[k] = constraints.real
        self._generator.set_state(state["rng"])
        self.num_updates = int(state["num_updates"])
