"""An update that fails on non-finite evidence leaves the critic able to train on the next good batch."""

import pytest
import torch

from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.critic import InferenceConfig, SubgoalCritic, TDBatch

GRAPH = SubgoalGraph(["a", "b", "c"], [("a", "b", 1)])


def batch(q_scale=1.0):
    g = torch.Generator().manual_seed(0)
    q = torch.randn(4, 3, generator=g) * q_scale
    return TDBatch(q_taken=torch.zeros(4), q_next=q, reward=torch.ones(4), discount=torch.ones(4))


@pytest.mark.parametrize("jit", [True, False])
def test_a_non_finite_loss_does_not_poison_later_updates(jit):
    critic = SubgoalCritic(GRAPH, config=InferenceConfig(jit=jit), seed=0)
    twin = SubgoalCritic(GRAPH, config=InferenceConfig(jit=jit), seed=0)
    for c in (critic, twin):
        c.update(batch())
        c.update(batch())
    with pytest.raises(FloatingPointError, match="critic loss is inf"):
        critic.update(batch(q_scale=1e30))       # residuals whose square overflows float32
    state = twin.state_dict()
    state["rng"] = critic.state_dict()["rng"]    # the failed step drew its samples
    twin.load_state_dict(state)
    diag, twin_diag = critic.update(batch()), twin.update(batch())
    assert diag["loss"] == twin_diag["loss"]
    assert torch.equal(critic.state_dict()["theta"], twin.state_dict()["theta"])
