"""CompiledTraceGraph_ELBO on a toy model of its own (the critic's use is in test_compiled.py): the same
losses, gradients, decaying-average baselines and extras as Pyro's eager TraceGraph_ELBO."""

import pyro
import pyro.distributions as dist
import pytest
import torch
from pyro.infer import TraceGraph_ELBO
from pyro.params.param_store import ParamStoreDict

from hubsgo_ppl.infer.compiled_elbo import CompiledTraceGraph_ELBO

BASELINE = "__baseline_avg_downstream_cost_w"


class Drawn(dist.Bernoulli):
    """Bernoulli(logits) whose sample is a draw made outside (as the critic's MH draws are): the trace
    then takes the draw as an input instead of recording a random op."""

    def __init__(self, logits, draw):
        super().__init__(logits=logits)
        self.draw = draw

    def expand(self, batch_shape, _instance=None):
        return Drawn(self.logits.expand(batch_shape), self.draw.expand(batch_shape))

    def sample(self, sample_shape=torch.Size()):
        return self.draw


class Toy:
    """w ~ Bernoulli(0.3) per row, y ~ Normal(2w - 1, 1); q(w) = Bernoulli(sigmoid(theta)), a decaying baseline."""

    def __init__(self):
        self.last_mean = None

    def model(self, y, draw):
        with pyro.plate("rows", y.shape[0]):
            w = pyro.sample("w", dist.Bernoulli(torch.full(y.shape, 0.3)))
            pyro.sample("y", dist.Normal(2 * w - 1, 1.0), obs=y)

    def guide(self, y, draw):
        theta = pyro.param("theta", torch.zeros(y.shape[0]))
        with pyro.plate("rows", y.shape[0]):
            w = pyro.sample("w", Drawn(theta, draw),
                            infer={"baseline": {"use_decaying_avg_baseline": True, "baseline_beta": 0.5}})
        self.last_mean = (w * theta).sum()


def _eager_step(state, toy, y, draw):
    with pyro.get_param_store().scope(state=state):
        loss = TraceGraph_ELBO().loss_and_grads(toy.model, toy.guide, y, draw)
    return loss


def _state():
    store = ParamStoreDict()
    with pyro.get_param_store().scope(state=store.get_state()):
        pyro.param("theta", torch.tensor([0.5, -1.0, 0.2]))
        return pyro.get_param_store().get_state()


def test_compiled_steps_equal_eager_steps():
    y = torch.tensor([1.2, -0.7, 0.1])
    eager_toy, comp_toy = Toy(), Toy()
    eager_state, comp_state = _state(), _state()
    elbo = CompiledTraceGraph_ELBO(comp_toy.model, comp_toy.guide, baseline_sites=("w",),
                                   extras=lambda: (comp_toy.last_mean,))
    elbo.compile_after = 2
    g = torch.Generator().manual_seed(0)
    for step in range(5):                                # call 1 eager (creates the baseline), 2 eager, then compiled
        draw = torch.bernoulli(torch.full((3,), 0.5), generator=g)
        want = _eager_step(eager_state, eager_toy, y, draw)
        got = elbo.step(comp_state, y, draw)
        assert got == pytest.approx(want, rel=1e-6), step
        a, b = eager_state["params"], comp_state["params"]
        torch.testing.assert_close(b["theta"].grad, a["theta"].grad)
        torch.testing.assert_close(b[BASELINE].detach(), a[BASELINE].detach())
        assert elbo.extra_values[0].item() == pytest.approx(eager_toy.last_mean.detach().item())
        for p in (a["theta"], b["theta"]):
            p.grad = None
    assert len(elbo._compiled) == 1                      # compiled once, reused


def test_loss_and_grads_refuses_another_model():
    toy = Toy()
    elbo = CompiledTraceGraph_ELBO(toy.model, toy.guide)
    with pytest.raises(ValueError, match="built for another model and guide"):
        elbo.loss_and_grads(Toy().model, toy.guide, torch.zeros(3), torch.zeros(3))
