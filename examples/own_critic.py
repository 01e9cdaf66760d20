"""A prior and a likelihood of your own, for a critic spec to name as ``own_critic:FewSubgoals`` and
``own_critic:Cauchy`` (docs/critic.md, "Your own prior or likelihood")."""

import pyro.distributions as dist
import torch

from hubsgo_ppl.infer import Likelihood, Prior


class FewSubgoals(Prior):
    """p(w) proportional to exp(-rate * |w|): each sub-goal in the set costs ``rate`` nats."""

    def __init__(self, graph, rate: float = 1.0):
        super().__init__(graph)
        self.rate = float(rate)

    def params(self):
        return {"rate": self.rate}

    def distribution(self):
        logits = torch.full((self.graph.n,), -self.rate)
        return dist.Bernoulli(logits=logits).to_event(1)


class Cauchy(Likelihood):
    """The TD residuals of Eq. 4 with Cauchy tails, so that a few large early errors weigh little."""

    def __init__(self, scale: float = 0.1):
        self.scale = float(scale)

    def params(self):
        return {"scale": self.scale}

    def distribution(self, loc):
        return dist.Cauchy(loc, torch.tensor(self.scale))
