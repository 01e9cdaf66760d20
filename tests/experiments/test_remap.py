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
