"""Reading the critic's q(w; lambda) (Sec. 3.4): the filtered set, G*, marginals, factors, log q, samples.

:class:`CriticReadout` holds the methods of :class:`~hubsgo_ppl.infer.critic.SubgoalCritic` that read
the guide without training it. They use the critic's parameters (``_theta``, ``_coupling``), graph
(``graph``, ``names``, ``n``, ``_edge_index``), settings (``config``), generator (``_generator``) and
samples (``_chains``, ``_last_samples``); none of them moves the parameters.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from ..distributions.mh_kernels import coupling_matrix, run_chains
from ..distributions.mrf import EXACT_LIMIT, PairwiseMRF

__all__ = ["CriticReadout", "unique_rows", "RANKING_DRAWS", "MARGINAL_CHAINS", "INDEPENDENT_BURN_IN_FACTOR",
           "NEAR_TIE_STANDARD_ERRORS"]

RANKING_DRAWS = 10_000  # independent draws behind G* (standard error of a probability <= 0.005)
MARGINAL_CHAINS = 4096  # fresh chains behind the marginals above exact_max_n before any update
# burn-in of a fresh chain whose end is one independent draw, as a multiple of the update's burn-in
# (which continues persistent chains instead of starting from random bits)
INDEPENDENT_BURN_IN_FACTOR = 4
NEAR_TIE_STANDARD_ERRORS = 2  # a G* entry this many standard errors from the top one is a near tie
FLOAT32_EXACT_WEIGHT = 1e4  # above this sum of |factors|, q is enumerated in float64 (float32 spacing ~1e-3 here)
_MAX_CODE_BITS = 62  # rows up to this width are counted as int64 codes in unique_rows


def unique_rows(w: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``torch.unique(w, dim=0, return_counts=True)`` for 0/1 rows ``(S, N)``: the distinct rows in
    lexicographic order and their counts. Up to N = 62 the rows are read as big-endian integers and
    counted with a 1-D unique (the same order, ~10x faster on a critic's 64 samples)."""
    n = w.shape[-1]
    if n > _MAX_CODE_BITS or w.device.type != "cpu" or w.dim() != 2:
        return torch.unique(w, dim=0, return_counts=True)
    shifts = np.arange(n - 1, -1, -1, dtype=np.int64)
    codes, counts = np.unique((w.detach().numpy().astype(np.int64) << shifts).sum(-1), return_counts=True)
    configs = torch.from_numpy(((codes[:, None] >> shifts) & 1).astype(np.float32)).to(w.dtype)
    return configs, torch.from_numpy(counts)


class CriticReadout:
    """The critic's readers (a mixin of :class:`~hubsgo_ppl.infer.critic.SubgoalCritic`)."""

    _unique: tuple | None = None  # (samples, configs, counts): _sample_counts' cache

    def last_samples(self) -> torch.Tensor:
        """The S samples drawn by the last update, (S, N)."""
        if self._last_samples is None:
            raise RuntimeError("no update has run yet; call update() first")
        return self._last_samples.clone()

    def filtered_set(self, given: torch.Tensor | None = None, complete_missing: bool = False) -> torch.Tensor:
        """Sec. 3.4: the most frequent configuration among the last update's samples, BoolTensor (N,).

        ``given`` (bool, (N,) or (B, N)) conditions on sub-goals already achieved: the most frequent
        configuration among the samples with ``w_i = 1`` for every given ``i``, i.e. the mode of the
        samples from q(w | w_given = 1). Where no sample agrees with a row, that row gets the
        unconditional mode, or with ``complete_missing`` q's completion of the row (:meth:`completion`: the
        route the agent is on, where the mode names one it can no longer take). The result has ``given``'s shape. Before the first update the samples are
        the current chain states. Ties go to the lexicographically smallest configuration.
        """
        _, configs, counts = self._sample_counts()
        mode = int(counts.argmax())
        if given is None:
            return configs[mode].bool()
        given = self._given_rows(given)
        rows = given.reshape(-1, self.n)
        # (B, U): configuration u holds every sub-goal row b gives, i.e. no given site is off in it; a
        # 0/1 matmul counts the given-but-off sites exactly (12x faster than a (B, U, N) broadcast)
        agree = (rows.to(configs.dtype) @ (1.0 - configs).T) == 0
        best = torch.where(agree, counts[None], torch.zeros_like(counts)[None]).argmax(-1)
        missing = ~agree.any(-1)
        best = torch.where(missing, torch.full_like(best, mode), best)
        out = configs[best].bool()
        if complete_missing and missing.any():
            out[missing] = self.completion(rows[missing]).bool()
        return out.reshape(given.shape)

    def _given_rows(self, given) -> torch.Tensor:
        """``given`` as a bool tensor of shape (N,) or (B, N); any other shape is refused."""
        given = torch.as_tensor(given, dtype=torch.bool)
        if given.shape[-1] != self.n or given.dim() not in (1, 2):
            raise ValueError(f"given must have shape ({self.n},) or (B, {self.n}), got {tuple(given.shape)}")
        return given

    def completion(self, given: torch.Tensor) -> torch.Tensor:
        """The configuration of highest log q reachable from ``given`` by single flips, with every given
        sub-goal held on: greedy coordinate ascent (iterated conditional modes) that flips, one at a
        time, the free site that raises log q most, until no flip raises it. BoolTensor with
        ``given``'s shape ((N,) or (B, N)); a local maximum of q(w | w_given = 1), not necessarily the
        global one (a set that only several flips together make more probable is not reached).

        Before any evidence q is the prior (``inference.init: prior``), so this is what the human's
        edges say completes what the agent already holds: with a key's positive edge to its door and
        the door's to the goal (field -2, strength 3), holding the key gives {key, door, goal}; holding
        nothing gives the empty set, every single flip from it lowering log q.
        """
        given = self._given_rows(given)
        rows = given.reshape(-1, self.n)
        theta = self._theta.detach().double()
        J = coupling_matrix(self._coupling.detach().double(), self._edge_index, self.n)
        w = rows.double()
        free = ~rows
        arange = torch.arange(rows.shape[0])
        for _ in range(2 * self.n + 1):            # each flip raises log q; a bound against float cycles
            gain = (1.0 - 2.0 * w) * (theta + w @ J)                  # log q change of flipping each site
            gain = torch.where(free, gain, torch.full_like(gain, -math.inf))
            best = gain.argmax(-1)
            up = gain[arange, best] > 0
            if not bool(up.any()):
                break
            w[arange[up], best[up]] = 1.0 - w[arange[up], best[up]]
        return w.bool().reshape(given.shape)

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

    def _independent_draws(self, num_draws: int, burn_in: int | None = None) -> torch.Tensor:
        """``num_draws`` independent samples (num_draws, N): the end of one fresh chain each, after
        ``burn_in`` sweeps (default :data:`INDEPENDENT_BURN_IN_FACTOR` x the config's)."""
        if burn_in is None:
            burn_in = INDEPENDENT_BURN_IN_FACTOR * self.config.burn_in
        return self.sample(1, num_chains=num_draws, burn_in=burn_in)[:, 0]

    def ranking(self, num_samples: int = RANKING_DRAWS, top_k: int = 5, burn_in: int | None = None) -> list[dict]:
        """G* (Sec. 3.4): rank configurations by empirical probability over ``num_samples`` draws.

        Each draw is the end of its own chain (``burn_in`` sweeps, default
        :data:`INDEPENDENT_BURN_IN_FACTOR` x the config's), so the draws are independent. ``near_tie``
        marks entries whose probability is within :data:`NEAR_TIE_STANDARD_ERRORS` standard errors of
        the top one's (the top entry too, if it has such a rival). ``exact_prob`` is the enumerated q(w)
        for N <= 20, else None.
        """
        if num_samples < 1 or top_k < 1:
            raise ValueError(f"need num_samples >= 1 and top_k >= 1, got {num_samples}, {top_k}")
        draws = self._independent_draws(num_samples, burn_in)
        configs, counts = torch.unique(draws, dim=0, return_counts=True)
        order = torch.argsort(counts, descending=True, stable=True)[:top_k]
        probs = counts[order].double() / num_samples
        exact = None
        if self.n <= EXACT_LIMIT:
            q = self._exact_distribution()
            exact = q.log_prob(configs[order].to(q.theta.dtype)).exp().tolist()
        top = float(probs[0])

        def close(p: float) -> bool:
            se = math.sqrt((top * (1 - top) + p * (1 - p)) / num_samples)
            return top - p <= NEAR_TIE_STANDARD_ERRORS * se

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
        at most 0.5 / sqrt(S)). Before any update, the mean of :data:`MARGINAL_CHAINS` independent draws."""
        if self.n <= self.config.exact_max_n:
            return self._exact_distribution().marginals().float()
        if self._last_samples is not None:
            return self._last_samples.mean(0)
        return self._independent_draws(MARGINAL_CHAINS).mean(0)

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
        if self.n > EXACT_LIMIT:
            return self.distribution(exact_max_n=0).log_prob(torch.as_tensor(w, dtype=torch.float32))
        q = self._exact_distribution()
        return q.log_prob(torch.as_tensor(w, dtype=q.theta.dtype)).float()

    def _exact_distribution(self) -> PairwiseMRF:
        """q for enumeration: in float64 where a state's log-weight, a sum of factors, may reach
        :data:`FLOAT32_EXACT_WEIGHT` in size (an Ising strength of 1e7, say), since float32 would lose the small
        differences between the states' weights, and their probabilities would no longer sum to 1."""
        theta, coupling = self._theta.detach(), self._coupling.detach()
        if float(theta.abs().sum() + coupling.abs().sum()) > FLOAT32_EXACT_WEIGHT:
            theta, coupling = theta.double(), coupling.double()
        return PairwiseMRF(theta.clone(), coupling.clone(), self._edge_index, burn_in=self.config.burn_in,
                           kernel=self.config.kernel, generator=self._generator, exact_max_n=EXACT_LIMIT)
