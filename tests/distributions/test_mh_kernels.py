"""The MH kernels' building blocks: the coupling matrix, the unnormalised log density (Eq. 1), the block
kernel's exactness on a small MRF, and run_chains' bookkeeping. (Chains against the exact distribution
for both kernels and the compiled scan are in tests/infer/test_mh.py.)"""

import itertools

import pytest
import torch

from hubsgo_ppl.distributions.mh_kernels import (block_flip_step, coupling_matrix, mh_steps, run_chains,
                                                 single_site_sweep, unnormalized_log_prob)

EDGES = torch.tensor([[0, 1], [1, 2], [0, 3]])
THETA = torch.tensor([0.5, -1.0, 0.3, 0.0])
COUPLING = torch.tensor([1.5, -2.0, 0.7])


def test_coupling_matrix_is_symmetric_with_zero_diagonal():
    mat = coupling_matrix(COUPLING, EDGES, 4)
    want = torch.zeros(4, 4)
    for (u, v), j in zip(EDGES.tolist(), COUPLING.tolist()):
        want[u, v] = want[v, u] = j
    assert torch.equal(mat, want)
    batched = coupling_matrix(torch.stack([COUPLING, 2 * COUPLING]), EDGES, 4)
    assert torch.equal(batched[1], 2 * want)
    assert torch.equal(coupling_matrix(torch.zeros(0), torch.zeros(0, 2, dtype=torch.long), 3), torch.zeros(3, 3))


def test_unnormalized_log_prob_is_theta_w_plus_pairwise_terms():
    states = torch.tensor(list(itertools.product([0.0, 1.0], repeat=4)))
    mat = coupling_matrix(COUPLING, EDGES, 4)
    got = unnormalized_log_prob(states, THETA, mat)
    for s, lp in zip(states, got):
        want = float(s @ THETA) + sum(j * float(s[u] * s[v]) for (u, v), j in zip(EDGES.tolist(), COUPLING.tolist()))
        assert float(lp) == pytest.approx(want, abs=1e-6)
    batched = unnormalized_log_prob(states[:2], torch.stack([THETA, THETA]), torch.stack([mat, mat]))
    assert torch.allclose(batched, got[:2])


def test_block_kernel_leaves_the_exact_distribution_invariant():
    states = torch.tensor(list(itertools.product([0.0, 1.0], repeat=4)))
    p = unnormalized_log_prob(states, THETA, coupling_matrix(COUPLING, EDGES, 4)).softmax(0)
    g = torch.Generator().manual_seed(0)
    start = states[torch.multinomial(p, 20_000, replacement=True, generator=g)]     # exact draws
    after = block_flip_step(start, THETA, COUPLING, EDGES, g, steps=2)
    codes = (after * torch.tensor([8.0, 4.0, 2.0, 1.0])).sum(-1).long()
    freq = torch.bincount(codes, minlength=16).double() / 20_000
    assert (freq - p.double()).abs().max() < 0.015


def test_kernels_are_seeded_and_validate_their_inputs():
    w = torch.zeros(6, 4)
    a = mh_steps(w, THETA, COUPLING, EDGES, torch.Generator().manual_seed(3), 5, kernel="block")
    b = mh_steps(w, THETA, COUPLING, EDGES, torch.Generator().manual_seed(3), 5, kernel="block")
    assert torch.equal(a, b) and set(a.unique().tolist()) <= {0.0, 1.0}
    assert torch.equal(mh_steps(w, THETA, COUPLING, EDGES, None, 0), w)
    with pytest.raises(ValueError, match="unknown MH kernel 'gibbs'"):
        mh_steps(w, THETA, COUPLING, EDGES, None, 1, kernel="gibbs")
    with pytest.raises(ValueError, match="chain states have 3 sites but theta has 4"):
        single_site_sweep(torch.zeros(2, 3), THETA, COUPLING, EDGES, None)
    with pytest.raises(ValueError, match="coupling has 2 entries but edge_index has 3 edges"):
        single_site_sweep(w, THETA, COUPLING[:2], EDGES, None)
    with pytest.raises(ValueError, match="block_size must be >= 1"):
        block_flip_step(w, THETA, COUPLING, EDGES, None, block_size=0)


def test_run_chains_records_thinned_states_after_burn_in():
    init = torch.tensor([[1.0, 0, 1, 0], [0.0, 1, 0, 1]])
    out = run_chains(THETA, COUPLING, EDGES, 2, 3, init=init, generator=torch.Generator().manual_seed(1),
                     thin=2, burn_in=4)
    g = torch.Generator().manual_seed(1)
    w = single_site_sweep(init, THETA, COUPLING, EDGES, g, sweeps=4)
    for t in range(3):
        w = single_site_sweep(w, THETA, COUPLING, EDGES, g, sweeps=2)
        assert torch.equal(out[:, t], w), t
    assert torch.equal(run_chains(THETA, COUPLING, EDGES, 2, 2), run_chains(THETA, COUPLING, EDGES, 2, 2))
    with pytest.raises(ValueError, match=r"init must have shape \(2, 4\)"):
        run_chains(THETA, COUPLING, EDGES, 2, 1, init=torch.zeros(3, 4))
    with pytest.raises(ValueError, match="need num_chains >= 1"):
        run_chains(THETA, COUPLING, EDGES, 0, 1)
