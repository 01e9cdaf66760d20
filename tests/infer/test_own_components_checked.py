"""A prior or likelihood of the user's own whose distribution cannot serve the critic (none defined, the
wrong shape, NaN) is refused when the spec is read, in one line naming the file, not at the first update."""

import sys

import pyro.distributions as dist
import pytest
import torch
import yaml

from hubsgo_ppl.infer import Likelihood, Prior
from hubsgo_ppl.infer.likelihoods import LIKELIHOODS
from hubsgo_ppl.infer.priors import PRIORS
from hubsgo_ppl.specs import SpecError, load_model_spec

NAMES = ["key", "door", "goal"]


class NoDistribution(Prior):
    pass


class ExtraSite(Prior):
    def distribution(self):
        return dist.Bernoulli(probs=torch.full((self.graph.n + 1,), 0.5)).to_event(1)


class NoEvent(Prior):
    def distribution(self):
        return dist.Bernoulli(probs=torch.full((self.graph.n,), 0.5))


class NaNPrior(Prior):
    def distribution(self):
        return dist.Bernoulli(logits=torch.full((self.graph.n,), float("nan")), validate_args=False).to_event(1)


class Tailed(Prior):
    def distribution(self):
        return dist.Bernoulli(logits=torch.full((self.graph.n,), -1.0)).to_event(1)


class RaisingPrior(Prior):
    def distribution(self):
        raise RuntimeError("cannot build")


class RaisingLogProb(Prior):
    def distribution(self):
        d = dist.Bernoulli(logits=torch.zeros(self.graph.n)).to_event(1)
        d.log_prob = lambda value: [][0]
        return d


class NoResidualDistribution(Likelihood):
    pass


class SummedResiduals(Likelihood):
    def distribution(self, loc):
        return dist.Normal(loc.sum(-1), 1.0)


class NaNLikelihood(Likelihood):
    def distribution(self, loc):
        return dist.Normal(loc * float("nan"), 1.0, validate_args=False)


class RaisingResiduals(Likelihood):
    def distribution(self, loc):
        raise RuntimeError("cannot score")


class RaisingOutcomes(Likelihood):
    evidence = "outcomes"

    def log_likelihood(self, w, outcomes):
        raise KeyError("episode")


class LaplaceTails(Likelihood):
    def distribution(self, loc):
        return dist.Laplace(loc, torch.tensor(0.5))


@pytest.fixture(autouse=True)
def _registries(monkeypatch):
    saved = dict(PRIORS), dict(LIKELIHOODS)
    monkeypatch.setitem(sys.modules, "own_checked", sys.modules[__name__])
    yield
    for table, before in zip((PRIORS, LIKELIHOODS), saved):
        table.clear()
        table.update(before)


def _load(tmp_path, prior, likelihood):
    path = tmp_path / "own.yaml"
    path.write_text(yaml.safe_dump({"name": "own", "subgoals": NAMES, "edges": [["key", "door", "positive"]],
                                    "prior": {"name": f"own_checked:{prior}"},
                                    "likelihood": {"name": f"own_checked:{likelihood}"}}))
    return load_model_spec(str(path))


def test_a_working_pair_loads(tmp_path):
    spec = _load(tmp_path, "Tailed", "LaplaceTails")
    assert spec.prior.name == "own_checked:Tailed"


@pytest.mark.parametrize("prior, likelihood, says", [
    ("NoDistribution", "LaplaceTails", "prior 'own_checked:NoDistribution' defines no distribution()"),
    ("ExtraSite", "LaplaceTails", "event shape (4,); it needs event shape (3,)"),
    ("NoEvent", "LaplaceTails", "batch shape (3,) and event shape (); it needs event shape (3,)"),
    ("NaNPrior", "LaplaceTails", "log_prob of the empty and the full set is [nan, nan]"),
    ("Tailed", "NoResidualDistribution", "likelihood 'own_checked:NoResidualDistribution' defines no distribution"),
    ("Tailed", "SummedResiduals", "has batch shape (2,) and event shape (); it needs loc's shape"),
    ("Tailed", "NaNLikelihood", "log_prob(0) of residuals"),
    ("RaisingPrior", "LaplaceTails", "distribution() raised RuntimeError: cannot build"),
    ("RaisingLogProb", "LaplaceTails", "log_prob of the empty and the full set raised IndexError"),
    ("Tailed", "RaisingResiduals", "distribution(loc) raised RuntimeError: cannot score"),
    ("Tailed", "RaisingOutcomes", "raised KeyError: 'episode'"),
])
def test_a_broken_distribution_is_refused_when_the_spec_is_read(tmp_path, prior, likelihood, says):
    with pytest.raises(SpecError) as err:
        _load(tmp_path, prior, likelihood)
    message = str(err.value)
    assert message.startswith(f"{tmp_path / 'own.yaml'}: ") and says in message, message
    assert "\n" not in message
