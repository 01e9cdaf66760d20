"""The enumerated readouts of q stay probabilities when the factors are large."""

import torch

from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.critic import SubgoalCritic
from hubsgo_ppl.infer.config import InferenceConfig


def _critic(strength: float) -> SubgoalCritic:
    graph = SubgoalGraph(["y_key", "y_door", "b_key", "b_door", "goal"],
                         [("y_key", "y_door", 1), ("b_key", "b_door", 1), ("y_key", "b_key", -1),
                          ("y_door", "b_door", -1), ("y_door", "goal", 1), ("b_door", "goal", 1)])
    return SubgoalCritic(graph, prior="ising", prior_params={"strength": strength, "field": -2.0},
                         likelihood="outcome", config=InferenceConfig(init="prior"), seed=0)


def test_marginals_and_exact_probs_with_a_huge_ising_strength():
    small, huge = _critic(1e3), _critic(1e8)        # both within the spec's range of numbers
    assert torch.allclose(huge.marginals(), small.marginals(), atol=1e-4)
    assert bool(((huge.marginals() >= 0) & (huge.marginals() <= 1)).all())
    rows = huge.ranking(num_samples=500, top_k=16)
    assert all(0.0 <= r["exact_prob"] <= 1.0 for r in rows)
    route = torch.tensor([1.0, 1.0, 0.0, 0.0, 1.0])
    assert abs(huge.log_q(route) - small.log_q(route)) < 1e-3
