"""TDBatch: the set-conditioned TD residuals of Eq. 2 against a loop over sets, pooling weights, validation."""

import itertools
import math

import pytest
import torch

from hubsgo_ppl.infer.tdbatch import TDBatch, td_residuals


def _batch(b=4, n=3, seed=0, masked=True, **kw):
    g = torch.Generator().manual_seed(seed)
    return TDBatch(q_taken=torch.randn(b, generator=g), q_next=torch.randn(b, n, generator=g),
                   reward=torch.rand(b, generator=g), discount=torch.full((b,), 0.9),
                   available=(torch.rand(b, n, generator=g) > 0.3) if masked else None, **kw)


@pytest.mark.parametrize("masked", [False, True])
def test_residuals_are_the_set_conditioned_target_minus_q(masked):
    batch = _batch(masked=masked)
    masks = torch.tensor(list(itertools.product([0.0, 1.0], repeat=3)))        # every G(w)
    res = batch.residuals(masks)
    assert res.shape == (8, 4)
    for i, w in enumerate(masks):
        for j in range(4):
            allowed = [k for k in range(3) if w[k] > 0.5 and (not masked or batch.available[j, k])]
            best = max((float(batch.q_next[j, k]) for k in allowed), default=0.0)   # an empty set bootstraps 0
            want = float(batch.reward[j]) + 0.9 * best - float(batch.q_taken[j])
            assert float(res[i, j]) == pytest.approx(want, abs=1e-6)
    assert torch.equal(td_residuals(masks, *batch.tensors()), res)
    assert len(batch.tensors()) == (5 if masked else 4) and batch.n == 3


def test_pooling_weights_mean_and_sum():
    a, b, c = _batch(seed=1), _batch(seed=2), _batch(seed=3, weight=0.5)
    mean, total = TDBatch.cat([a, b, c]), TDBatch.cat([a, b, c], reduce="sum")
    assert mean.weight == pytest.approx((1 + 1 + 0.5) / 9) and total.weight == pytest.approx(2.5 / 3)
    assert torch.equal(mean.q_next, torch.cat([a.q_next, b.q_next, c.q_next]))
    assert torch.equal(mean.available, torch.cat([a.available, b.available, c.available]))
    assert TDBatch.cat([a]) is a
    with pytest.raises(ValueError, match="at least one batch"):
        TDBatch.cat([])
    with pytest.raises(ValueError, match="reduce must be 'mean' or 'sum'"):
        TDBatch.cat([a, b], reduce="max")
    with pytest.raises(ValueError, match="either every batch has an `available` mask or none has"):
        TDBatch.cat([a, _batch(masked=False)])


def test_construction_converts_detaches_and_validates():
    q = torch.randn(2, 3, requires_grad=True)
    batch = TDBatch(q_taken=[0.0, 1.0], q_next=q, reward=[0, 1], discount=[0.9, 0.9], outcomes=[[1, 0, 1]])
    assert not batch.q_next.requires_grad and batch.reward.dtype == torch.float32
    assert batch.outcomes.dtype == torch.float32 and batch.outcomes.tolist() == [[1.0, 0.0, 1.0]]
    bad = [(dict(q_next=torch.zeros(3)), "q_next must have shape"),
           (dict(reward=torch.zeros(3)), r"reward must have shape \(2,\)"),
           (dict(available=torch.ones(2, 2, dtype=torch.bool)), "available must have q_next's shape"),
           (dict(outcomes=torch.ones(1, 2)), r"outcomes must have shape \(E, 3\)"),
           (dict(outcomes=torch.tensor([[1.0, math.nan, 0.0]])), "outcomes must hold 0 or 1"),
           (dict(outcomes=torch.tensor([[1.0, 0.5, math.inf]])), "outcomes must hold 0 or 1"),
           (dict(weight=0.0), "weight must be a positive number"),
           (dict(reward=torch.tensor([0.0, math.nan])), "reward has NaN or inf")]
    base = dict(q_taken=torch.zeros(2), q_next=torch.zeros(2, 3), reward=torch.zeros(2), discount=torch.ones(2))
    for change, message in bad:
        with pytest.raises(ValueError, match=message):
            TDBatch(**{**base, **change})
    with pytest.raises(ValueError, match="masks have 2 sub-goals but q_next has 3"):
        TDBatch(**base).residuals(torch.ones(2))
