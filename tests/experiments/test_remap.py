"""Remapping learned state onto another sub-goal set by name (the rules of experiments/remap.py)."""

import torch

from hubsgo_ppl.experiments.remap import name_index, remap_rows


def test_name_index_maps_each_new_name_to_its_old_position():
    assert name_index(["a", "b", "c"], ["c", "x", "a"]) == [2, None, 0]
    assert name_index([], ["a"]) == [None]


def test_remap_rows_copies_persisting_blocks_and_starts_new_ones_at_the_kept_mean():
    old = torch.arange(12.0).reshape(6, 2)            # 3 sub-goals x blocks of 2 rows
    fresh = torch.full((6, 2), -1.0)
    out = remap_rows(old, fresh, [2, None, 0], block=2)
    assert torch.equal(out[0:2], old[4:6]) and torch.equal(out[4:6], old[0:2])
    kept_mean = (old[4:6] + old[0:2]) / 2                 # blocks 2 and 0 carried over
    assert torch.equal(out[2:4], kept_mean)
    assert torch.equal(fresh, torch.full((6, 2), -1.0))   # the fresh tensor is not modified
    # nothing carried over: a new block is the mean of all old blocks
    alone = remap_rows(old, torch.zeros(2, 2), [None], block=2)
    assert torch.allclose(alone, old.reshape(3, 2, 2).mean(0))


def _updated_critic(edges, exact_max_n=0):
    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.infer.critic import InferenceConfig, SubgoalCritic

    graph = SubgoalGraph(["a", "b", "c"], edges)
    return SubgoalCritic(graph, config=InferenceConfig(exact_max_n=exact_max_n, num_samples=8, burn_in=2), seed=0)


def test_a_revised_critic_reads_its_marginals_from_its_own_q_not_the_old_samples():
    """Above exact_max_n the marginals are the mean of the last update's samples; those were drawn from
    the old q, so a revision that changes q (an edge added) drops them, and one that keeps q keeps them."""
    from hubsgo_ppl.experiments.remap import remap_critic_state

    old = _updated_critic([("a", "b", 1)])
    old.update(lambda w: w.sum(-1, keepdim=True) - 1.0)
    kept, _ = remap_critic_state(old.state_dict(), _updated_critic([("a", "b", 1)]), keep_run=True)
    assert torch.equal(kept["last_samples"], old.state_dict()["last_samples"])
    revised = _updated_critic([("a", "b", 1), ("b", "c", 1)])
    state, _ = remap_critic_state(old.state_dict(), revised, keep_run=True)
    assert state["last_samples"] is None
    revised.load_state_dict(state)
    assert revised.marginals().shape == (3,)       # fresh draws from the revised q
