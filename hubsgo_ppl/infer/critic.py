"""The HUBS-GO sub-goal critic: black-box VI of q(w; lambda) with TraceGraph_ELBO (Sec. 3.3-3.4).

Model (Eq. 3-4)::

    w ~ p(w)                                    prior over indicator vectors (default uniform)
    0 ~ f(. | r(w)),  r(w) = y_G(w) - Q(s, g)   residuals of the minibatch, likelihood f (Eq. 4)

Guide: the pairwise MRF q(w; lambda) of Eq. 1 whose ``theta`` (unary) and ``coupling`` (pairwise)
are ``pyro.param`` s, initialised to 0 and ``init_scale * edge sign``, or to the prior itself with
``init="prior"``. The guide's sample site draws w with our MH kernels from persistent chains (S
chains, ``burn_in`` sweeps from their last state per update).
``TraceGraph_ELBO(num_particles=S, vectorize_particles=True)`` then gives the score-function gradient
of Eq. 5, L(lambda) = E_q[L_G] + KL(q || p), with a decaying-average baseline; one
:meth:`SubgoalCritic.update` is lines 9-11 of Algorithm 1.

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
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np
import pyro
import pyro.distributions as dist
import torch
from pyro.infer import TraceGraph_ELBO
from pyro.ops.provenance import detach_provenance, get_provenance
from torch.distributions import constraints

from ..distributions._provenance import WithProvenance, untrack
from ..distributions.mrf import EXACT_LIMIT, PairwiseMRF
from ..graph import SubgoalGraph
from .compiled_elbo import CompiledTraceGraph_ELBO
from .likelihoods import get_likelihood
from .mh import KERNELS, ChromaticScan, mh_steps, run_chains
from .priors import get_prior
from .tdbatch import TDBatch, td_residuals

if TYPE_CHECKING:  # pragma: no cover
    from ..specs import ModelSpec

__all__ = ["InferenceConfig", "TDBatch", "SubgoalCritic", "CompiledTraceGraph_ELBO", "td_residuals", "unique_rows"]

_SIGN_NAMES = {"positive": 1, "negative": -1, "unknown": 0}
VALIDATE = ("first", "always", "never")
INITS = ("edges", "prior")


@dataclass
class InferenceConfig:
    """Settings of the critic's inference (paper defaults: burn-in 32, 64 samples per update)."""

    lr: float = 0.05  # Adam step size for theta and J
    burn_in: int = 32  # MH sweeps per update, from the chains' last state
    num_samples: int = 64  # S: MH chains = vectorised ELBO particles per update
    kernel: str = "single_site"  # "single_site" (chromatic flip sweeps) or "block"
    baseline_beta: float = 0.9  # decay of TraceGraph_ELBO's average baseline (variance reduction)
    init_scale: float = 1.0  # initial coupling = init_scale * human edge sign (init="edges")
    # where q starts: "edges" (theta = 0, J = init_scale * edge sign) or "prior" (q = p(w), so KL = 0
    # before any data; needs a prior the guide's family holds, e.g. bernoulli or ising)
    init: str = "edges"
    exact_max_n: int = 16  # exact log Z for N <= this; leave-one-out score above
    # Pyro's validation (distribution arguments, site shapes, NaN/inf warnings) on the "first" update
    # only, on "always" or "never": it costs ~20% of an update, and a custom prior or likelihood that
    # passes it once passes it every time (the shapes do not change between updates)
    pyro_validation: str = "first"
    # compile the TraceGraph_ELBO step for TDBatch updates with torch.jit.trace (CompiledTraceGraph_ELBO):
    # the same estimator and the same numbers, an update ~3.4x faster (benchmarks/critic.py --floor);
    # callables always run eagerly
    jit: bool = True

    def __post_init__(self):
        def bad(key, why):
            raise ValueError(f"InferenceConfig.{key} = {getattr(self, key)!r}: {why}")

        if not (isinstance(self.lr, (int, float)) and math.isfinite(self.lr) and self.lr > 0):
            bad("lr", "must be a positive number, e.g. 0.05")
        if int(self.burn_in) != self.burn_in or self.burn_in < 0:
            bad("burn_in", "must be an integer >= 0, e.g. 32")
        if int(self.num_samples) != self.num_samples or self.num_samples < 2:
            bad("num_samples", "must be an integer >= 2 (the leave-one-out score needs two chains), e.g. 64")
        if self.kernel not in KERNELS:
            bad("kernel", f"use one of: {', '.join(KERNELS)}")
        if not 0.0 <= self.baseline_beta < 1.0:
            bad("baseline_beta", "must be in [0, 1), e.g. 0.9")
        if not math.isfinite(self.init_scale):
            bad("init_scale", "must be finite")
        if int(self.exact_max_n) != self.exact_max_n or not 0 <= self.exact_max_n <= EXACT_LIMIT:
            bad("exact_max_n", f"must be an integer in 0..{EXACT_LIMIT}")
        if self.init not in INITS:
            bad("init", f"use one of: {', '.join(INITS)}")
        if self.pyro_validation not in VALIDATE:
            bad("pyro_validation", f"use one of: {', '.join(VALIDATE)}")
        if not isinstance(self.jit, bool):
            bad("jit", "must be true or false")
        self.burn_in, self.num_samples, self.exact_max_n = int(self.burn_in), int(self.num_samples), int(self.exact_max_n)


def unique_rows(w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``torch.unique(w, dim=0, return_counts=True)`` for 0/1 rows ``(S, N)``: the distinct rows in
    lexicographic order and their counts. Up to N = 62 the rows are read as big-endian integers and
    counted with a 1-D unique (the same order, ~10x faster on a critic's 64 samples)."""
    n = w.shape[-1]
    if n > 62 or w.device.type != "cpu" or w.dim() != 2:
        return torch.unique(w, dim=0, return_counts=True)
    shifts = np.arange(n - 1, -1, -1, dtype=np.int64)
    codes, counts = np.unique((w.detach().numpy().astype(np.int64) << shifts).sum(-1), return_counts=True)
    configs = torch.from_numpy(((codes[:, None] >> shifts) & 1).astype(np.float32)).to(w.dtype)
    return configs, torch.from_numpy(counts)


class SubgoalCritic:
    """The Bayesian sub-goal critic q(w; lambda) of Sec. 3.3, trained by :meth:`update` (Alg. 1, 9-11).

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
        config: InferenceConfig | None = None,
        seed: int = 0,
    ):
        if not isinstance(graph, SubgoalGraph):
            raise TypeError(f"graph must be a SubgoalGraph, got {type(graph).__name__}")
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
        self._batch_site: tuple = ()  # (guide distribution, sample) of the last guide call, eager or compiled
        self._compiled_elbo = CompiledTraceGraph_ELBO(
            self._batch_model, self._batch_guide, baseline_sites=("w",), extras=self._batch_stats,
            num_particles=cfg.num_samples, vectorize_particles=True, max_plate_nesting=0,
        ) if cfg.jit else None
        self._chains = torch.randint(0, 2, (cfg.num_samples, self.n), generator=self._generator).float()
        self._scan = ChromaticScan(self._edge_index, self.n) if cfg.kernel == "single_site" else None
        self._last_samples: torch.Tensor | None = None
        self._unique: tuple | None = None       # (samples, configs, counts) for filtered_set's reads
        self.num_updates = 0

    @classmethod
    def from_spec(cls, spec: "ModelSpec", seed: int = 0) -> "SubgoalCritic":
        """Build a critic from a validated :class:`hubsgo_ppl.specs.ModelSpec`."""
        graph = SubgoalGraph(spec.subgoals, [(u, v, _SIGN_NAMES[s]) for u, v, s in spec.edges]).preset(spec.graph)
        prior = spec.prior.model_dump()
        likelihood = spec.likelihood.model_dump()
        return cls(
            graph,
            prior=prior.pop("name"),
            prior_params=prior,
            likelihood=likelihood.pop("name"),
            likelihood_params=likelihood,
            config=InferenceConfig(**spec.inference.model_dump()),
            seed=seed,
        )

    # -- Pyro model and guide ------------------------------------------------------------------

    def _model(self, residual_fn: Callable[[torch.Tensor], torch.Tensor], weight: float = 1.0) -> None:
        w = pyro.sample("w", self._prior_dist)
        if self.likelihood.evidence == "outcomes":      # residual_fn is the outcomes tensor (E, N)
            self._observe_outcomes(w, residual_fn, weight)
            return
        r = residual_fn(w)
        self._check_residuals(r, w)
        r, prov = untrack(r)
        lik = WithProvenance(self.likelihood.distribution(r).to_event(1), prov)
        with pyro.poutine.scale(scale=weight):
            pyro.sample("td", lik, obs=torch.zeros(r.shape))

    def _guide(self, residual_fn, weight: float = 1.0) -> None:
        cfg = self.config
        d = PairwiseMRF(
            pyro.param("theta"),
            pyro.param("coupling"),
            self._edge_index,
            burn_in=cfg.burn_in,
            kernel=cfg.kernel,
            init=self._chains,
            generator=self._generator,
            exact_max_n=cfg.exact_max_n,
            validate_args=False,
        )
        w = pyro.sample("w", d, infer={"baseline": self._baseline})
        self._batch_site = (d, w)
        self._chains = detach_provenance(w).detach().clone()

    def _observe_outcomes(self, w: torch.Tensor, outcomes: torch.Tensor, weight: float) -> None:
        """The outcome evidence: ``log_likelihood(w, outcomes)`` as a factor that depends on w."""
        plain, prov = untrack(w)
        ll = self.likelihood.log_likelihood(plain, outcomes)
        with pyro.poutine.scale(scale=weight):
            pyro.sample("outcomes", WithProvenance(dist.Unit(ll), prov), obs=torch.zeros(ll.shape + (0,)))

    # The same model and guide for a TDBatch, with every tensor an argument (what torch.jit.trace needs)
    # and the guide's MH draw made before the call (our kernels use a torch.Generator, which a trace
    # cannot carry): the guide's site returns those draws, as the eager guide's sample() would.

    def _batch_model(self, draws, *tensors, weight: float = 1.0) -> None:
        w = pyro.sample("w", self._prior_dist)
        if self.likelihood.evidence == "outcomes":
            self._observe_outcomes(w, tensors[0], weight)
            return
        r, prov = untrack(td_residuals(w, *tensors))
        lik = WithProvenance(self.likelihood.distribution(r).to_event(1), prov)
        with pyro.poutine.scale(scale=weight):
            pyro.sample("td", lik, obs=torch.zeros(r.shape))

    def _batch_guide(self, draws, *tensors, weight: float = 1.0) -> None:
        d = PairwiseMRF(pyro.param("theta"), pyro.param("coupling"), self._edge_index, burn_in=0,
                        init=draws, exact_max_n=self.config.exact_max_n, validate_args=False)
        w = pyro.sample("w", d, infer={"baseline": self._baseline})
        self._batch_site = (d, w)

    def _batch_stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The update's diagnostics from the last guide call (outputs of the compiled step): mean log q(w)
        of the samples under q before the step (for the entropy; Pyro's own log_prob of them is cached)
        and the mean set size."""
        d, w = self._batch_site
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

    def _as_fn(self, residual_fn) -> tuple[Callable[[torch.Tensor], torch.Tensor], float]:
        """The residual function and the likelihood weight (a TDBatch's ``weight``, else 1)."""
        if isinstance(residual_fn, TDBatch):
            if residual_fn.n != self.n:
                raise ValueError(f"TDBatch has {residual_fn.n} sub-goal columns but the critic has N = {self.n}")
            if self.likelihood.evidence == "outcomes":
                if residual_fn.outcomes is None or residual_fn.outcomes.shape[0] == 0:
                    raise ValueError(f"the {self.likelihood.registered_name!r} likelihood scores outcomes, and "
                                     "this TDBatch has none; attach the achieved sets of successful episodes")
                return residual_fn.outcomes, residual_fn.weight
            return residual_fn.residuals, residual_fn.weight
        if self.likelihood.evidence == "outcomes":
            raise TypeError(f"the {self.likelihood.registered_name!r} likelihood scores outcomes: pass a TDBatch "
                            "with `outcomes`, not a residual function")
        if not callable(residual_fn):
            raise TypeError(f"update() takes a TDBatch or a callable residual_fn, got {type(residual_fn).__name__}")
        return residual_fn, 1.0

    def _loss_and_grads(self, residual_fn) -> float:
        fn, weight = self._as_fn(residual_fn)
        self._theta.grad = None
        self._coupling.grad = None
        validate = self.config.pyro_validation == "always" or (
            self.config.pyro_validation == "first" and self.num_updates == 0)
        if self._compiled_elbo is not None and isinstance(residual_fn, TDBatch) and not validate:
            draws = self._draw()
            inputs = (fn,) if self.likelihood.evidence == "outcomes" else residual_fn.tensors()
            loss = self._compiled_elbo.step(self._param_state, draws, *inputs, weight=weight)
            self._chains = draws
            self._step_stats = self._compiled_elbo.extra_values
        else:
            with pyro.get_param_store().scope(state=self._param_state), pyro.validation_enabled(validate):
                loss = self._elbo.loss_and_grads(self._model, self._guide, fn, weight)
            with torch.no_grad():
                self._step_stats = tuple(x.detach() for x in self._batch_stats())
        self._last_samples = self._chains
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
                m = samples.mean(0).clamp(1e-6, 1 - 1e-6)
                entropy, exact = float(-(m * m.log() + (1 - m) * (1 - m).log()).sum()), 0.0
            self._optim.step()
            theta, coupling = self._theta.detach().numpy(), self._coupling.detach().numpy()   # views
            if not (np.isfinite(theta).all() and np.isfinite(coupling).all()):
                raise FloatingPointError("critic parameters became non-finite after the step; lower InferenceConfig.lr")
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

    # -- reading the critic ------------------------------------------------------------------

    def last_samples(self) -> torch.Tensor:
        """The S samples drawn by the last update, (S, N)."""
        if self._last_samples is None:
            raise RuntimeError("no update has run yet; call update() first")
        return self._last_samples.clone()

    def filtered_set(self, given: torch.Tensor | None = None) -> torch.Tensor:
        """Sec. 3.4: the most frequent configuration among the last update's samples, BoolTensor (N,).

        ``given`` (bool, (N,) or (B, N)) conditions on sub-goals already achieved: the most frequent
        configuration among the samples with ``w_i = 1`` for every given ``i``, i.e. the mode of the
        samples from q(w | w_given = 1). Where no sample agrees with a row, that row gets the
        unconditional mode. The result has ``given``'s shape. Before the first update the samples are
        the current chain states. Ties go to the lexicographically smallest configuration.
        """
        _, configs, counts = self._sample_counts()
        mode = int(counts.argmax())
        if given is None:
            return configs[mode].bool()
        given = torch.as_tensor(given, dtype=torch.bool)
        if given.shape[-1] != self.n or given.dim() not in (1, 2):
            raise ValueError(f"given must have shape ({self.n},) or (B, {self.n}), got {tuple(given.shape)}")
        rows = given.reshape(-1, self.n)
        agree = (configs.bool()[None] | ~rows[:, None]).all(-1)                 # (B, U)
        best = torch.where(agree, counts[None], torch.zeros_like(counts)[None]).argmax(-1)
        best = torch.where(agree.any(-1), best, torch.full_like(best, mode))
        return configs[best].bool().reshape(given.shape)

    def _sample_counts(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """``(samples, configs, counts)``: the distinct configurations among the last update's samples
        (the chain states before any update), in lexicographic order, and how often each occurs.
        Cached until the samples change."""
        samples = self._last_samples if self._last_samples is not None else self._chains
        if self._unique is None or self._unique[0] is not samples:     # new samples replace the tensor
            self._unique = (samples, *unique_rows(samples))
        return self._unique

    def distribution(self, exact_max_n: int | None = None) -> PairwiseMRF:
        """The current q(w; lambda) as a detached :class:`PairwiseMRF`."""
        return PairwiseMRF(
            self._theta.detach().clone(),
            self._coupling.detach().clone(),
            self._edge_index,
            burn_in=self.config.burn_in,
            kernel=self.config.kernel,
            generator=self._generator,
            exact_max_n=self.config.exact_max_n if exact_max_n is None else exact_max_n,
        )

    def sample(self, num_samples: int, num_chains: int = 1, burn_in: int | None = None) -> torch.Tensor:
        """Fresh chains from random bits: ``burn_in`` sweeps, then one sample per sweep.

        Returns ``(num_chains, num_samples, N)``; uses (and advances) the critic's generator.
        """
        return run_chains(
            self._theta.detach(),
            self._coupling.detach(),
            self._edge_index,
            num_chains=num_chains,
            num_steps=num_samples,
            kernel=self.config.kernel,
            generator=self._generator,
            burn_in=self.config.burn_in if burn_in is None else burn_in,
        )

    def ranking(self, num_samples: int = 10_000, top_k: int = 5, burn_in: int | None = None) -> list[dict]:
        """G* (Sec. 3.4): rank configurations by empirical probability over ``num_samples`` draws.

        Each draw is the end of its own chain (``burn_in`` sweeps, default 4x the config's), so the
        draws are independent. ``near_tie`` marks entries whose probability is within two standard
        errors of the top one's (the top entry too, if it has such a rival). ``exact_prob`` is the
        enumerated q(w) for N <= 20, else None.
        """
        if num_samples < 1 or top_k < 1:
            raise ValueError(f"need num_samples >= 1 and top_k >= 1, got {num_samples}, {top_k}")
        draws = self.sample(1, num_chains=num_samples, burn_in=4 * self.config.burn_in if burn_in is None else burn_in)[:, 0]
        configs, counts = torch.unique(draws, dim=0, return_counts=True)
        order = torch.argsort(counts, descending=True, stable=True)[:top_k]
        probs = counts[order].double() / num_samples
        exact = None
        if self.n <= EXACT_LIMIT:
            exact = self.distribution(exact_max_n=EXACT_LIMIT).log_prob(configs[order]).exp().tolist()
        top = float(probs[0])

        def close(p: float) -> bool:
            se = math.sqrt((top * (1 - top) + p * (1 - p)) / num_samples)
            return top - p <= 2 * se

        ties = [close(float(p)) for p in probs]
        ties[0] = any(ties[1:])
        out = []
        for j, idx in enumerate(order.tolist()):
            mask = configs[idx].long().tolist()
            out.append(
                {
                    "subgoals": [name for name, m in zip(self.names, mask) if m],
                    "mask": mask,
                    "prob": float(probs[j]),
                    "exact_prob": None if exact is None else float(exact[j]),
                    "near_tie": bool(ties[j]),
                }
            )
        return out

    def marginals(self) -> torch.Tensor:
        """P(w_i = 1): exact up to N = ``exact_max_n``; above it, the mean of the S samples the last update
        drew (no extra sampling, so a diagnostic read costs nothing next to an update; standard error
        at most 0.5 / sqrt(S)). Before any update, the mean of 4096 fresh chains."""
        if self.n <= self.config.exact_max_n:
            return self.distribution(exact_max_n=EXACT_LIMIT).marginals()
        if self._last_samples is not None:
            return self._last_samples.mean(0)
        return self.sample(1, num_chains=4096, burn_in=4 * self.config.burn_in)[:, 0].mean(0)

    def factors(self) -> dict[str, dict]:
        """The guide's factors: ``{"unary": {name: theta}, "pairwise": {(u, v): J_uv}}``."""
        theta = self._theta.detach().tolist()
        coupling = self._coupling.detach().tolist()
        return {
            "unary": dict(zip(self.names, theta)),
            "pairwise": {(u, v): c for (u, v, _), c in zip(self.graph.edges, coupling)},
        }

    def log_q(self, w: torch.Tensor) -> torch.Tensor:
        """log q(w; lambda): normalised for N <= 20, else unnormalised (lacks -log Z)."""
        return self.distribution(exact_max_n=min(self.n, EXACT_LIMIT)).log_prob(torch.as_tensor(w, dtype=torch.float32))

    # -- checkpoints -------------------------------------------------------------------------

    def state_dict(self) -> dict:
        """Parameters, optimiser, chains, baseline and RNG state, plus plain config (no callables)."""
        baseline = {k: v.detach().clone() for k, v in self._param_state["params"].items() if k.startswith("__baseline")}
        return {
            "names": list(self.names),
            "edges": [list(e) for e in self.graph.edges],
            "config": asdict(self.config),
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
