import math

import pytest
import torch

from hubsgo_ppl.distributions import PairwiseMRF, state_table
from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.priors import PRIORS, Prior, get_prior, register_prior

G = SubgoalGraph(["a", "b", "c", "d"], [("a", "b", 1), ("b", "c", -1), ("c", "d", 0)])


def test_registry_has_the_three_priors():
    assert {"bernoulli", "beta_bernoulli", "ising"} <= set(PRIORS)


@pytest.mark.parametrize("name, params", [("bernoulli", {}), ("bernoulli", {"p": 0.2}), ("beta_bernoulli", {"alpha": 0.5, "beta": 2.0}), ("ising", {"strength": 1.5, "field": -0.3})])
def test_priors_are_normalised_over_all_states(name, params):
    d = get_prior(name, G, **params).distribution()
    assert d.event_shape == (4,)
    lp = d.log_prob(state_table(4))
    assert torch.logsumexp(lp, 0).item() == pytest.approx(0.0, abs=1e-5)


def test_default_bernoulli_is_uniform():
    lp = get_prior("bernoulli", G).distribution().log_prob(state_table(4))
    assert torch.allclose(lp, torch.full((16,), -4 * math.log(2)))


def test_beta_bernoulli_is_exchangeable_and_matches_formula():
    d = get_prior("beta_bernoulli", G, alpha=2.0, beta=3.0).distribution()
    w1, w2 = torch.tensor([1.0, 0, 1, 0]), torch.tensor([0.0, 1, 0, 1])
    assert d.log_prob(w1).item() == pytest.approx(d.log_prob(w2).item())
    beta = lambda a, b: math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)  # noqa: E731
    assert d.log_prob(w1).item() == pytest.approx(beta(4, 5) - beta(2, 3), abs=1e-5)


@pytest.mark.parametrize("name, params", [("bernoulli", {"p": 0.3}), ("beta_bernoulli", {"alpha": 0.5, "beta": 2.0})])
def test_prior_sampling_matches_probabilities(name, params):
    d = get_prior(name, G, **params).distribution()
    s = d.sample((40_000,))
    codes = (s.long() * (2 ** torch.arange(4))).sum(-1)
    emp = torch.bincount(codes, minlength=16).double() / 40_000
    p = d.log_prob(state_table(4)).exp().double()
    assert 0.5 * float((emp - p).abs().sum()) < 0.02


def test_ising_couplings_follow_edge_signs():
    d = get_prior("ising", G, strength=2.0, field=0.5).distribution()
    assert isinstance(d, PairwiseMRF)
    assert d.coupling.tolist() == [2.0, -2.0, 0.0]
    assert d.theta.tolist() == [0.5] * 4


@pytest.mark.parametrize(
    "name, params, match",
    [
        ("bernoulli", {"p": 1.5}, "p must be in"),
        ("beta_bernoulli", {"alpha": -1}, "alpha must be a positive"),
        ("bernoulli", {"q": 0.1}, "unknown parameter.*accepted: p"),
        ("dirichlet", {}, "registered: .*bernoulli"),
    ],
)
def test_bad_priors(name, params, match):
    with pytest.raises(ValueError, match=match):
        get_prior(name, G, **params)


def test_user_registered_prior():
    @register_prior("all_on_test")
    class AllOn(Prior):
        def __init__(self, graph, p: float = 0.9):
            super().__init__(graph)
            self.p = p

        def distribution(self):
            return get_prior("bernoulli", self.graph, p=self.p).distribution()

    try:
        assert get_prior("all_on_test", G).distribution().log_prob(torch.ones(4)).item() == pytest.approx(4 * math.log(0.9))
        with pytest.raises(ValueError, match="already registered"):
            register_prior("all_on_test")(type("Other", (Prior,), {"distribution": lambda self: None}))
    finally:
        PRIORS.pop("all_on_test")
