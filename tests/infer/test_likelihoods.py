import math

import pytest
import torch

from hubsgo_ppl.infer.likelihoods import LIKELIHOODS, Likelihood, get_likelihood, register_likelihood

R = torch.tensor([-2.0, -0.5, 0.0, 1.0, 3.0])


def test_gaussian_is_minus_td_loss_plus_constant():
    # Eq. 4: log p(y | w) = -1/2 (y - Q)^2 + const = -L_G + const for scale 1.
    lp = get_likelihood("gaussian").distribution(R).log_prob(torch.zeros(5))
    assert torch.allclose(lp, -0.5 * R**2 - 0.5 * math.log(2 * math.pi))
    lp2 = get_likelihood("gaussian", scale=2.0).distribution(R).log_prob(torch.zeros(5))
    assert torch.allclose(lp2, -R**2 / 8 - math.log(2.0) - 0.5 * math.log(2 * math.pi))


def test_student_t_and_laplace_values():
    lap = get_likelihood("laplace", scale=0.5).distribution(R).log_prob(torch.zeros(5))
    assert torch.allclose(lap, -R.abs() / 0.5 - math.log(2 * 0.5))
    t = get_likelihood("student_t", df=3.0, scale=1.0).distribution(R).log_prob(torch.zeros(5))
    c = math.lgamma(2.0) - math.lgamma(1.5) - 0.5 * math.log(3 * math.pi)
    assert torch.allclose(t, c - 2.0 * torch.log1p(R**2 / 3), atol=1e-5)
    # heavier tails: a huge residual costs less than under the Gaussian
    big = torch.tensor([10.0])
    heavy = get_likelihood("student_t").distribution(big).log_prob(torch.zeros(1))
    assert heavy > get_likelihood("gaussian").distribution(big).log_prob(torch.zeros(1))


@pytest.mark.parametrize(
    "name, params, match",
    [
        ("gaussian", {"scale": 0}, "scale must be > 0"),
        ("gaussian", {"scale": -1}, "scale must be > 0"),
        ("student_t", {"df": -3}, "df must be > 0"),
        ("laplace", {"sigma": 1}, "unknown parameter.*accepted: scale"),
        ("cauchy", {}, "registered: gaussian, laplace, outcome, student_t"),
    ],
)
def test_bad_likelihoods(name, params, match):
    with pytest.raises(ValueError, match=match):
        get_likelihood(name, **params)


def test_user_registered_likelihood():
    @register_likelihood("wide_gaussian_test")
    class Wide(Likelihood):
        def distribution(self, loc):
            return get_likelihood("gaussian", scale=10.0).distribution(loc)

    try:
        assert "wide_gaussian_test" in LIKELIHOODS
        assert get_likelihood("wide_gaussian_test").distribution(R).batch_shape == (5,)
    finally:
        LIKELIHOODS.pop("wide_gaussian_test")


def test_outcome_likelihood_is_a_mixture_over_episodes():
    lik = get_likelihood("outcome", flip=0.1, power=1.0)
    outcomes = torch.tensor([[1.0, 1.0, 0.0], [0.0, 1.0, 1.0]])
    w = torch.tensor([[1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    # by hand: mismatches per episode (0, 2), (2, 2), (1, 1)
    def per(d):
        return d * math.log(0.1) + (3 - d) * math.log(0.9)
    expected = [math.log(0.5 * (math.exp(per(a)) + math.exp(per(b)))) for a, b in ((0, 2), (2, 2), (1, 1))]
    assert torch.allclose(lik.log_likelihood(w, outcomes), torch.tensor(expected), atol=1e-6)
    assert lik.evidence == "outcomes" and lik.params() == {"flip": 0.1, "power": 1.0, "settled_power": 0.4}
    assert lik.settled_scale() == 1.0          # settling never weakens the evidence: max(power, settled_power)
    # tempered: the default power 0.25 scales the whole log-likelihood, mixture included
    tempered = get_likelihood("outcome", flip=0.1)
    assert tempered.params() == {"flip": 0.1, "power": 0.25, "settled_power": 0.4}
    assert tempered.settled_scale() == pytest.approx(1.6)
    assert get_likelihood("gaussian").settled_scale() == 1.0
    assert torch.allclose(tempered.log_likelihood(w, outcomes), 0.25 * torch.tensor(expected), atol=1e-6)
    with pytest.raises(ValueError, match="flip must be < 0.5"):
        get_likelihood("outcome", flip=0.7)
    for bad in (0, -1, float("nan"), "x"):
        with pytest.raises(ValueError, match="power must be"):
            get_likelihood("outcome", power=bad)
        with pytest.raises(ValueError, match="settled_power must be"):
            get_likelihood("outcome", settled_power=bad)
    with pytest.raises(ValueError, match="outcomes must have shape"):
        lik.log_likelihood(w, torch.zeros(0, 3))


def test_td_likelihood_log_likelihood_sums_the_residual_densities():
    from hubsgo_ppl.infer.tdbatch import TDBatch

    batch = TDBatch(q_taken=torch.zeros(2), q_next=torch.tensor([[1.0, 2.0], [0.5, -1.0]]),
                    reward=torch.tensor([0.0, 1.0]), discount=torch.ones(2))
    w = torch.tensor([[1.0, 0.0], [0.0, 1.0]])
    lik = get_likelihood("gaussian", scale=0.5)
    expected = lik.distribution(batch.residuals(w)).log_prob(torch.zeros(())).sum(-1)
    assert torch.allclose(lik.log_likelihood(w, *batch.tensors()), expected)


def test_a_bad_flip_is_refused_with_an_example_the_outcome_likelihood_takes():
    with pytest.raises(ValueError, match=r"flip must be > 0, got -0.1; e.g. flip: (\S+)") as err:
        get_likelihood("outcome", flip=-0.1)
    example = float(str(err.value).rsplit("flip: ", 1)[1])
    assert get_likelihood("outcome", flip=example).flip == example
