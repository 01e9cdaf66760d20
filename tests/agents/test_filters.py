"""The sub-goal filters: HUBS-GO's critic filter (the batch weight, the safeguard, outcome evidence) and h-DQN's none."""

import dataclasses
import re

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.config import ConfigError, make_config
from hubsgo_ppl.agents.filters import CriticFilter, NoFilter
from hubsgo_ppl.agents.settings import LoopConfig
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


def goal_dropping_critic(seed=0):
    """A critic whose prior all but forbids the goal: Ĝt from it leaves the goal out."""
    c = SubgoalCritic(GRAPH, prior="ising", prior_params={"strength": 0.5, "field": -6.0},
                      likelihood_params={"scale": 1.0}, seed=seed)
    sd = c.state_dict()
    sd["theta"] = torch.tensor([4.0, 4.0, -4.0, -4.0, -8.0])   # q's mode: {yk, yd}, never the goal
    c.load_state_dict(sd)
    return c


def test_safeguard_keeps_what_the_recent_successes_needed():
    f = CriticFilter(goal_dropping_critic(), outcome_window=4, keep_fraction=0.5)
    f.update(batches(1)[0])
    assert f.allowed().tolist() == [True, True, False, False, False]      # no success yet: no guard
    visited = np.array([True, True, False, False, True])
    f.end_episode(visited, success=False)                                  # failures are not evidence
    assert not f.allowed()[4]
    f.end_episode(visited, success=True)
    assert f.allowed().tolist() == [True, True, False, False, True]      # the goal is back
    # given achieved sub-goals (B, N), every row gets the guard
    rows = f.allowed(np.array([[False] * 5, [True, False, False, False, False]]))
    assert rows[:, 4].all()
    # a sub-goal in fewer than keep_fraction of the window's successes is not kept
    other = np.array([False, False, True, True, True])
    for _ in range(3):
        f.end_episode(other, success=True)                                 # window: 1 x visited, 3 x other
    kept = f.allowed()
    assert kept[4] and kept[2] and kept[3]                                 # in 3/4 and 4/4 of them
    f.end_episode(other, success=True)                                     # visited leaves the window
    sd = f.state_dict()
    g = CriticFilter(goal_dropping_critic(), outcome_window=4, keep_fraction=0.5)
    g.load_state_dict(sd)
    assert torch.equal(g.outcomes(), f.outcomes()) and (g.allowed() == f.allowed()).all()


def test_default_safeguard_keeps_what_every_recent_success_achieved():
    f = CriticFilter(goal_dropping_critic(), outcome_window=3)       # keep_fraction 1: the intersection
    f.update(batches(1)[0])
    f.end_episode(np.array([False, False, True, True, True]), success=True)
    assert f.allowed().tolist() == [True, True, True, True, True]          # one success: all it achieved
    f.end_episode(np.array([False, False, True, False, True]), success=True)
    assert f.allowed().tolist() == [True, True, True, False, True]         # b2 missed once: the critic's call
    for _ in range(2):                                                     # the first success leaves the window
        f.end_episode(np.array([False, False, True, True, True]), success=True)
    assert f.allowed().tolist() == [True, True, True, False, True]         # still missed by one of the three
    f.end_episode(np.array([False, False, True, True, True]), success=True)
    assert f.allowed().tolist() == [True, True, True, True, True]


def test_safeguard_can_be_turned_off_and_bad_values_are_refused():
    f = CriticFilter(goal_dropping_critic(), keep_fraction=0.0)
    f.update(batches(1)[0])
    f.end_episode(np.ones(5, dtype=bool), success=True)
    assert not f.allowed()[4]
    # the filter's settings are the loop's, checked where they are declared
    for key, value, says in [("filter_keep", 1.5, "a number in [0, 1]"), ("outcome_window", 0, "an integer >= 1"),
                             ("filter_end", 1.2, "a number in [0, 1]")]:
        with pytest.raises(ConfigError, match=rf"^loop.{key} takes {re.escape(says)} \(default .*\), got {value}$"):
            make_config("loop", LoopConfig, {key: value}, total_steps=10)
    # the loop's own guard in both families: a share of the decisions reads G0
    assert LoopConfig.minigrid().filter_end < 1.0 and LoopConfig.robosuite().filter_end < 1.0


def test_outcome_critic_waits_for_the_first_success_then_learns_the_route():
    # the evidence at full weight (power 1): three successes name the route against the field of -2
    c = SubgoalCritic(GRAPH, prior="ising", prior_params={"strength": 3.0, "field": -2.0},
                      likelihood="outcome", likelihood_params={"power": 1.0}, seed=0)
    f = CriticFilter(c)
    assert f.update(batches(1)[0]) == {} and f.allowed() is None           # no evidence: Ĝt = G0
    route = np.array([False, False, True, True, True])
    for _ in range(3):
        f.end_episode(route, success=True)
    for b in batches(150, seed=1):
        stats = f.update(b)
    assert stats["critic/set_size"] == 3.0
    assert f.allowed().tolist() == route.tolist()
    assert c.ranking(num_samples=2000, top_k=1)[0]["subgoals"] == ["bk", "bd", "goal"]


def test_no_filter_offers_g0_and_holds_no_state():
    f = NoFilter()
    assert f.allowed() is None and f.allowed(np.ones(5, dtype=bool)) is None
    assert f.update(batches(1)[0]) == {} and f.end_episode(np.ones(5, dtype=bool), success=True) is None
    assert f.state_dict() == {}
    f.load_state_dict({})
    with pytest.raises(ValueError, match="NoFilter has no state"):
        f.load_state_dict(CriticFilter(critic()).state_dict())


def test_critic_filter_is_g0_until_its_first_update_then_the_critics_mode():
    c, twin = critic(), critic()
    f = CriticFilter(c)
    assert f.allowed() is None
    batch = batches(1)[0]
    d = f.update(batch)
    direct = twin.update(batch)                       # the same critic updated without the filter
    mode = c.filtered_set().numpy()
    assert f.allowed().tolist() == mode.tolist()
    assert d["critic/set_size"] == mode.sum() and d["critic/kept"] == 0.0
    assert {k: d[f"critic/{k}"] for k in ("loss", "elbo", "entropy")} == {k: direct[k] for k in ("loss", "elbo",
                                                                                                "entropy")}
    np.testing.assert_allclose(f.marginals(), c.marginals().numpy())
    fresh = CriticFilter(critic(seed=9))
    fresh.load_state_dict(f.state_dict())
    assert fresh.allowed().tolist() == mode.tolist()


def test_before_its_first_update_the_filter_can_read_the_priors_completion():
    graph = SubgoalGraph(["yk", "yd", "bk", "bd", "goal", "x"],
                         [("yk", "yd", 1), ("bk", "bd", 1), ("yk", "bk", -1), ("yd", "bd", -1),
                          ("yd", "goal", 1), ("bd", "goal", 1)])
    from hubsgo_ppl.infer.critic import InferenceConfig

    def prior_critic():
        return SubgoalCritic(graph, prior="ising", prior_params={"strength": 3.0, "field": -2.0},
                             likelihood="outcome", config=InferenceConfig(init="prior"), seed=0)

    f = CriticFilter(prior_critic(), before_update="completion")
    holds_bk = np.array([False, False, True, False, False, False])
    assert f.allowed(holds_bk).tolist() == [False, False, True, True, True, False]
    rows = np.stack([holds_bk, np.zeros(6, dtype=bool)])
    assert f.allowed(rows).tolist() == [[False, False, True, True, True, False], [False] * 6]
    assert not f.allowed().any()                      # holding nothing: empty, and the loop reads G0
    assert CriticFilter(prior_critic()).allowed(holds_bk) is None      # the default: G0 until the first update
    f.end_episode(np.array([True, True, False, False, True, False]), success=True)
    q = torch.rand(16, 6, generator=torch.Generator().manual_seed(0))
    f.update(TDBatch(q[:, 0], q, torch.zeros(16), torch.full((16,), 0.9)))   # after it: the critic's mode
    assert f.allowed(holds_bk).tolist() == (f.critic.filtered_set(given=torch.as_tensor(holds_bk)).numpy()
                                            | f._keep).tolist()
    with pytest.raises(ConfigError, match=r"^loop.filter_before_update takes one of 'g0', 'completion' "):
        make_config("loop", LoopConfig, {"filter_before_update": "prior"})

