"""MH kernels against exact enumeration: total variation <= 0.03 from 20,000 samples.

TV tolerance: for i.i.d. sampling the expected TV of an empirical distribution is about
0.5 * sqrt(2 / (pi * n)) * sum_w sqrt(p(w)); the test MRFs are drawn so that this baseline is
<= 0.02 at n = 20,000, so 0.03 leaves room only for a small MCMC error. The negative control
shows a sampler that ignores the couplings fails the same check.
"""

import pickle

import pyro
import pytest
import torch

from hubsgo_ppl.distributions import PairwiseMRF, mh_kernels, state_table
from hubsgo_ppl.distributions.mh_kernels import block_flip_step, run_chains, single_site_sweep
from hubsgo_ppl.infer import mh
from hubsgo_ppl.infer.mh import MRFMHKernel

TV_TOL = 0.03


def random_mrf(n, seed):
    # Larger N spreads mass over more states; stronger factors keep the i.i.d. TV baseline <= 0.02.
    scale = 1.5 if n < 10 else 2.5
    g = torch.Generator().manual_seed(seed)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if torch.rand((), generator=g) < 0.5 or j == i + 1]
    ei = torch.tensor(pairs, dtype=torch.long)
    theta = scale * torch.randn(n, generator=g)
    coupling = scale * torch.randn(len(pairs), generator=g)
    return theta, coupling, ei


def tv(samples, theta, coupling, ei):
    n = theta.shape[0]
    p = PairwiseMRF(theta, coupling, ei).probs().double()
    codes = (samples.reshape(-1, n).long() * (2 ** torch.arange(n))).sum(-1)
    emp = torch.bincount(codes, minlength=2**n).double() / codes.shape[0]
    iid_noise = 0.5 * (2 / (torch.pi * codes.shape[0])) ** 0.5 * p.sqrt().sum()
    return 0.5 * float((emp - p).abs().sum()), float(iid_noise)


@pytest.mark.parametrize("kernel", ["single_site", "block"])
@pytest.mark.parametrize("n", [3, 6, 10])
def test_batched_chains_match_exact_distribution(n, kernel):
    theta, coupling, ei = random_mrf(n, seed=10 + n)
    gen = torch.Generator().manual_seed(n)
    samples = run_chains(theta, coupling, ei, num_chains=1000, num_steps=20, kernel=kernel, generator=gen, thin=2, burn_in=30)
    assert samples.shape == (1000, 20, n)
    dist_tv, noise = tv(samples, theta, coupling, ei)
    assert noise <= 0.02, "test MRF too flat for a meaningful 0.03 check"
    assert dist_tv <= TV_TOL, (dist_tv, noise)


def test_negative_control_ignoring_couplings_fails_the_check():
    theta, coupling, ei = random_mrf(6, seed=16)
    samples = run_chains(theta, torch.zeros_like(coupling), ei, 1000, 20, generator=torch.Generator().manual_seed(0), burn_in=30)
    assert tv(samples, theta, coupling, ei)[0] > 3 * TV_TOL


def _graph(kind: str, n: int) -> torch.Tensor:
    pairs = {
        "chain": [(i, i + 1) for i in range(n - 1)],
        "bipartite": [(i, j) for i in range(n // 2) for j in range(n // 2, n)],   # two classes of n/2
        "complete": [(i, j) for i in range(n) for j in range(i + 1, n)],          # n classes of one
        "none": [],
    }[kind]
    return torch.tensor(pairs, dtype=torch.long).reshape(-1, 2)


@pytest.mark.parametrize("kind", ["chain", "bipartite", "complete", "none"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_compiled_scan_is_the_eager_loop_to_the_last_bit(kind, dtype):
    """Flat chains run in numba (ChromaticScan); they must give exactly the eager torch loop's states and
    leave the generator where the eager loop leaves it, for any graph, chain count and sweep count."""
    n = 8
    ei = _graph(kind, n)
    g = torch.Generator().manual_seed(len(kind))
    for num_chains, sweeps in [(1, 1), (64, 32), (300, 70)]:
        theta = 2 * torch.randn(n, generator=g, dtype=dtype)
        coupling = 2 * torch.randn(ei.shape[0], generator=g, dtype=dtype)
        w = torch.randint(0, 2, (num_chains, n), generator=g).to(dtype)
        ga, gb = torch.Generator().manual_seed(sweeps), torch.Generator().manual_seed(sweeps)
        compiled = single_site_sweep(w, theta, coupling, ei, ga, sweeps=sweeps)
        eager = mh_kernels._eager_sweeps(w, theta, coupling, ei, gb, sweeps)
        assert compiled.dtype == eager.dtype == dtype
        assert torch.equal(compiled, eager), (kind, num_chains, sweeps)
        assert torch.equal(ga.get_state(), gb.get_state())


def test_compiled_scan_blocks_of_uniforms_keep_the_stream(monkeypatch):
    """Uniforms are drawn in blocks of sweeps (capped in memory); the block size must not change a draw."""
    theta, coupling, ei = random_mrf(6, seed=3)
    w = torch.zeros(50, 6)
    full = single_site_sweep(w, theta, coupling, ei, torch.Generator().manual_seed(4), sweeps=40)
    monkeypatch.setattr(mh_kernels, "_LOG_U_ELEMENTS", 50 * 6 * 3)     # three sweeps per block
    assert torch.equal(full, single_site_sweep(w, theta, coupling, ei, torch.Generator().manual_seed(4), sweeps=40))


def test_infer_mh_re_exports_the_kernels():
    """The critic and older callers import the kernels from infer.mh; they are the distribution's."""
    for name in ("KERNELS", "ChromaticScan", "coupling_matrix", "single_site_sweep", "block_flip_step",
                 "mh_steps", "run_chains", "_eager_sweeps"):
        assert getattr(mh, name) is getattr(mh_kernels, name), name


def test_kernels_keep_shapes_and_are_seeded():
    theta, coupling, ei = random_mrf(5, seed=1)
    w = torch.zeros(4, 3, 5)
    a = single_site_sweep(w, theta, coupling, ei, torch.Generator().manual_seed(1), sweeps=3)
    b = single_site_sweep(w, theta, coupling, ei, torch.Generator().manual_seed(1), sweeps=3)
    assert a.shape == w.shape and torch.equal(a, b)
    c = block_flip_step(w, theta, coupling, ei, torch.Generator().manual_seed(1), steps=2)
    assert c.shape == w.shape and set(c.unique().tolist()) <= {0.0, 1.0}
    with pytest.raises(ValueError, match="sites"):
        single_site_sweep(torch.zeros(2, 4), theta, coupling, ei, None)
    with pytest.raises(ValueError, match="one coupling per edge"):
        single_site_sweep(torch.zeros(2, 5), theta, coupling[:-1], ei, None)


def test_batched_parameters_sample_each_member():
    # (B, N) parameters with (S, B, N) chains: each batch member follows its own MRF.
    g = torch.Generator().manual_seed(2)
    ei = torch.tensor([[0, 1], [1, 2]])
    theta = torch.randn(2, 3, generator=g) * 1.5
    coupling = torch.randn(2, 2, generator=g) * 1.5
    w = torch.zeros(8000, 2, 3)
    w = single_site_sweep(w, theta, coupling, ei, g, sweeps=30)
    for b in range(2):
        assert tv(w[:, b], theta[b], coupling[b], ei)[0] <= TV_TOL


def _mcmc_samples(n, kernel, num_samples, seed, steps_per_sample=1):
    theta, coupling, ei = random_mrf(n, seed=10 + n)
    k = MRFMHKernel(theta, coupling, ei, kernel=kernel, seed=seed, steps_per_sample=steps_per_sample)
    mcmc = pyro.infer.MCMC(k, num_samples=num_samples, warmup_steps=50, disable_progbar=True)
    mcmc.run()
    return mcmc, mcmc.get_samples()["w"], (theta, coupling, ei)


def test_pyro_mcmc_route_matches_exact_distribution():
    mcmc, w, params = _mcmc_samples(3, "single_site", 20_000, seed=0)
    assert w.shape == (20_000, 3)
    assert tv(w, *params)[0] <= TV_TOL


# One pyro.infer.MCMC step costs ~0.3 ms of Pyro bookkeeping (more for the block kernel), so the
# 20,000-sample runs for N = 6, 10 and the block kernel take 10-100 s each: slow tier.
@pytest.mark.slow
@pytest.mark.parametrize(
    "n, kernel", [(3, "block"), (6, "single_site"), (6, "block"), (10, "single_site"), (10, "block")]
)
def test_pyro_mcmc_route_matches_exact_distribution_larger(n, kernel):
    mcmc, w, params = _mcmc_samples(n, kernel, 20_000, seed=0, steps_per_sample=2)
    assert tv(w, *params)[0] <= TV_TOL


def test_mcmc_kernel_seed_alone_fixes_the_draws_whatever_torch_was_seeded_with():
    seed, state = torch.initial_seed(), torch.get_rng_state()
    try:
        draws = []
        for global_seed in (1, 2):      # a fresh process starts torch at a random initial seed
            torch.manual_seed(global_seed)
            draws.append(_mcmc_samples(3, "single_site", 200, seed=0)[1])
    finally:
        torch.manual_seed(seed)
        torch.set_rng_state(state)
    assert torch.equal(draws[0], draws[1])


def test_mcmc_kernel_several_chains_pickles_and_differs():
    theta, coupling, ei = random_mrf(4, seed=3)
    k = MRFMHKernel(theta, coupling, ei, seed=5)
    k.setup(0)
    clone = pickle.loads(pickle.dumps(k))
    assert clone.transforms == {} and clone._generator is None
    mcmc = pyro.infer.MCMC(k, num_samples=200, warmup_steps=10, num_chains=2, disable_progbar=True,
                           initial_params={"w": torch.tensor([[0.0, 0, 0, 0], [1.0, 1, 1, 1]])})
    mcmc.run()
    w = mcmc.get_samples(group_by_chain=True)["w"]
    assert w.shape == (2, 200, 4)
    assert not torch.equal(w[0], w[1])


def test_state_table_limit():
    with pytest.raises(ValueError, match="N <= 20"):
        state_table(21)
