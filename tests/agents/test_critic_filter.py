"""HUBS-GO's critic filter hands the minibatch, with its likelihood weight, to the critic."""

import dataclasses

import pytest
import torch

from hubsgo_ppl.agents.filters import CriticFilter
from hubsgo_ppl.agents.loop import LoopConfig
from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.critic import SubgoalCritic, TDBatch

GRAPH = SubgoalGraph(["yk", "yd", "bk", "bd", "goal"],
                     [("yk", "yd", 1), ("bk", "bd", 1), ("yk", "bk", -1), ("yd", "bd", -1)])


def batches(count, b=16, seed=0):
    g = torch.Generator().manual_seed(seed)
    out = []
    for _ in range(count):
        q = torch.rand(b, 5, generator=g)
        out.append(TDBatch(q[:, 0], q, (torch.rand(b, generator=g) > 0.7).float(), torch.full((b,), 0.9),
                           available=torch.rand(b, 5, generator=g) > 0.3))
    return out


def critic(seed=3):
    return SubgoalCritic(GRAPH, prior="ising", prior_params={"strength": 3.0, "field": -2.0},
                         likelihood_params={"scale": 0.1}, seed=seed)


def test_critic_filter_hands_the_batch_weight_to_the_critic():
    # a pooled minibatch at weight 1/4 must move the critic like weight 1/4, not like weight 1
    b = TDBatch.cat(batches(4))
    assert b.weight == 0.25
    via_filter, direct, unweighted = critic(), critic(), critic()
    CriticFilter(via_filter).update(b)
    direct.update(b)
    unweighted.update(dataclasses.replace(b, weight=1.0))
    assert torch.equal(via_filter._theta, direct._theta)
    assert not torch.equal(via_filter._theta, unweighted._theta)


def test_loop_config_pool_weight():
    assert LoopConfig().critic_pool_weight == "mean"
    with pytest.raises(ValueError, match="critic_pool_weight must be 'mean' or 'sum'"):
        LoopConfig(critic_pool_weight="max")
