import itertools
import math

import pytest
import torch

from hubsgo_ppl.distributions import PairwiseMRF, state_table
from hubsgo_ppl.distributions.mh_kernels import coupling_matrix


def random_mrf(n, seed, dense=True, batch=()):
    g = torch.Generator().manual_seed(seed)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)] if dense else [(i, i + 1) for i in range(n - 1)]
    ei = torch.tensor(pairs, dtype=torch.long).reshape(-1, 2)
    return torch.randn(batch + (n,), generator=g), torch.randn(batch + (len(pairs),), generator=g), ei


def brute_force(theta, coupling, ei):
    n = theta.shape[-1]
    states = torch.tensor(list(itertools.product([0.0, 1.0], repeat=n)))
    lw = []
    for s in states:
        v = float((theta * s).sum())
        for (u, w), j in zip(ei.tolist(), coupling.tolist()):
            v += j * float(s[u] * s[w])
        lw.append(v)
    lw = torch.tensor(lw, dtype=torch.float64)
    return states, lw, torch.logsumexp(lw, 0)


@pytest.mark.parametrize("n", [1, 3, 5])
def test_log_prob_log_z_marginals_match_brute_force(n):
    theta, coupling, ei = random_mrf(n, seed=n)
    d = PairwiseMRF(theta, coupling, ei)
    states, lw, log_z = brute_force(theta, coupling, ei)
    assert d.log_partition().item() == pytest.approx(log_z.item(), abs=1e-5)
    assert torch.allclose(d.log_prob(states).double(), lw - log_z, atol=1e-5)
    p = torch.exp(lw - log_z)
    assert torch.allclose(d.marginals().double(), (p[:, None] * states.double()).sum(0), atol=1e-5)
    assert d.probs().sum().item() == pytest.approx(1.0, abs=1e-5)
    assert d.entropy().item() == pytest.approx(float(-(p * p.log()).sum()), abs=1e-4)


def test_probs_follow_state_table_order():
    theta, coupling, ei = random_mrf(4, seed=0)
    d = PairwiseMRF(theta, coupling, ei)
    table = state_table(4)
    assert table[5].tolist() == [1.0, 0.0, 1.0, 0.0]  # bit i of k is w_i
    assert torch.allclose(d.probs(), d.log_prob(table).exp(), atol=1e-6)


def test_chunked_enumeration_agrees_with_a_single_block():
    # N = 17 goes through the 2^16-state chunks; compare with one explicit logsumexp.
    theta, coupling, ei = random_mrf(17, seed=3, dense=False)
    d = PairwiseMRF(theta.double(), coupling.double(), ei)
    states = state_table(17, torch.float64)
    mat = coupling_matrix(coupling.double(), ei, 17)
    direct = torch.logsumexp(states @ theta.double() + 0.5 * ((states @ mat) * states).sum(-1), 0)
    assert d.log_partition().item() == pytest.approx(direct.item(), rel=1e-10)


def test_log_partition_gradient_is_the_mean_sufficient_statistic():
    theta, coupling, ei = random_mrf(5, seed=1)
    theta.requires_grad_(True)
    coupling.requires_grad_(True)
    d = PairwiseMRF(theta, coupling, ei)
    d.log_partition().backward()
    p = d.probs().detach()
    s = state_table(5)
    assert torch.allclose(theta.grad, p @ s, atol=1e-5)
    pair = s[:, ei[:, 0]] * s[:, ei[:, 1]]
    assert torch.allclose(coupling.grad, p @ pair, atol=1e-5)


def test_batched_parameters_and_expand():
    theta, coupling, ei = random_mrf(4, seed=2, batch=(3,))
    d = PairwiseMRF(theta, coupling, ei)
    assert d.batch_shape == (3,) and d.event_shape == (4,)
    for b in range(3):
        single = PairwiseMRF(theta[b], coupling[b], ei)
        assert torch.allclose(d.probs()[b], single.probs(), atol=1e-6)
    e = PairwiseMRF(theta[0], coupling[0], ei).expand((7,))
    assert type(e) is PairwiseMRF and e.batch_shape == (7,)
    assert e.sample().shape == (7, 4)
    assert e.log_prob(torch.ones(7, 4)).shape == (7,)
    assert d.enumerate_support().shape == (16, 3, 4)


def test_leave_one_out_score_above_exact_max_n():
    theta, coupling, ei = random_mrf(4, seed=4)
    d = PairwiseMRF(theta, coupling, ei, exact_max_n=2).expand((5,))
    w = torch.randint(0, 2, (5, 4), generator=torch.Generator().manual_seed(0)).float()
    parts = d.score_parts(w)
    lq = d.unnormalized_log_prob(w)
    assert torch.allclose(parts.log_prob, lq)
    expected = torch.stack([lq[p] - (lq.sum() - lq[p]) / 4 for p in range(5)])
    assert torch.allclose(parts.score_function, expected, atol=1e-6)
    assert abs(float(parts.score_function.sum())) < 1e-5  # centred: a constant cost adds no gradient
    with pytest.raises(ValueError, match="needs enumeration"):
        d.log_partition()
    with pytest.raises(ValueError, match=">= 2 independent particles"):
        PairwiseMRF(theta, coupling, ei, exact_max_n=2).score_parts(w[0])


def test_sample_starts_from_init_and_is_seeded():
    theta, coupling, ei = random_mrf(6, seed=5)
    init = torch.ones(10, 6)
    d0 = PairwiseMRF(theta, coupling, ei, burn_in=0, init=init)
    assert torch.equal(d0.expand((10,)).sample(), init)
    a = PairwiseMRF(theta, coupling, ei, generator=torch.Generator().manual_seed(9)).sample((50,))
    b = PairwiseMRF(theta, coupling, ei, generator=torch.Generator().manual_seed(9)).sample((50,))
    assert torch.equal(a, b) and a.shape == (50, 6)
    assert set(a.unique().tolist()) <= {0.0, 1.0}


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(coupling=torch.zeros(2)), "coupling must have shape"),
        (dict(edge_index=torch.tensor([[0, 9]])), "outside"),
        (dict(edge_index=torch.tensor([[1, 1]])), "self-edge"),
        (dict(kernel="gibbs"), "unknown MH kernel"),
        (dict(burn_in=-1), "burn_in"),
        (dict(exact_max_n=30), "exact_max_n"),
        (dict(init=torch.full((3,), 2.0)), "init must be a 0/1"),
    ],
)
def test_bad_arguments(kwargs, match):
    args = dict(theta=torch.zeros(3), coupling=torch.zeros(1), edge_index=torch.tensor([[0, 1]]))
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        PairwiseMRF(args.pop("theta"), args.pop("coupling"), args.pop("edge_index"), **args)


def test_trace_enum_elbo_gives_the_exact_kl():
    # Enumerating the guide's support turns the ELBO into an exact sum: loss = KL(q || p) here.
    import pyro
    import pyro.distributions as dist
    from pyro.infer import TraceEnum_ELBO, config_enumerate

    theta, coupling, ei = random_mrf(3, seed=6)
    q = PairwiseMRF(theta, coupling, ei)
    prior = dist.Bernoulli(torch.full((3,), 0.3)).to_event(1)

    def model():
        pyro.sample("w", prior)

    @config_enumerate
    def guide():
        pyro.sample("w", q)

    loss = TraceEnum_ELBO(max_plate_nesting=0).loss(model, guide)
    s = state_table(3)
    p = q.probs()
    kl = float((p * (q.log_prob(s) - prior.log_prob(s))).sum())
    assert loss == pytest.approx(kl, abs=1e-5)
    assert math.isfinite(loss)
