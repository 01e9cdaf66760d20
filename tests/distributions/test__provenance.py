"""Provenance helpers: strip a TraceGraph_ELBO provenance tag, put the same one back, and a wrapper
whose log_prob carries it."""

import torch
from pyro.distributions import Bernoulli
from pyro.ops.provenance import ProvenanceTensor, get_provenance, track_provenance

from hubsgo_ppl.distributions._provenance import WithProvenance, retrack, to_batch_shape, untrack


def test_untrack_then_retrack_keeps_the_value_and_the_tag():
    x = torch.tensor([0.0, 1.0, 1.0])
    tagged = track_provenance(x, frozenset({"w"}))
    plain, prov = untrack(tagged)
    assert not isinstance(plain, ProvenanceTensor) and torch.equal(plain, x) and prov == frozenset({"w"})
    back = retrack(plain * 2, prov)
    assert get_provenance(back) == frozenset({"w"}) and torch.equal(back, 2 * x)
    assert untrack(x) == (x, frozenset())
    assert retrack(x, frozenset()) is x                      # no tag: no wrapper


def test_to_batch_shape_expands_only_when_needed():
    lp = torch.tensor(1.5)
    assert to_batch_shape(lp, torch.Size([3])).tolist() == [1.5, 1.5, 1.5]
    same = torch.zeros(2, 3)
    assert to_batch_shape(same, torch.Size([2, 3])) is same
    assert to_batch_shape(torch.zeros(3), torch.Size([2, 3])).shape == (2, 3)


def test_with_provenance_log_prob_equals_the_base_and_carries_the_tag():
    base = Bernoulli(probs=torch.tensor([0.2, 0.7])).to_event(1)
    d = WithProvenance(base, frozenset({"site"}))
    value = track_provenance(torch.tensor([1.0, 0.0]), frozenset({"other"}))
    lp = d.log_prob(value)
    assert get_provenance(lp) == frozenset({"site"})          # the wrapper's tag, not the value's
    assert torch.allclose(untrack(lp)[0], base.log_prob(torch.tensor([1.0, 0.0])))
    assert (d.batch_shape, d.event_shape) == (base.batch_shape, base.event_shape)
    wide = d.expand(torch.Size([4]))
    assert isinstance(wide, WithProvenance) and wide.batch_shape == (4,) and wide.provenance == d.provenance
    assert d.sample(torch.Size([5])).shape == (5, 2)
