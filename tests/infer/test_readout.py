"""The critic's readers: unique_rows, the filtered set (given achieved sub-goals), G*, log q and the
sampled marginals above the exact limit."""

import pytest
import torch

from hubsgo_ppl.distributions import state_table
from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.critic import InferenceConfig, SubgoalCritic
from hubsgo_ppl.infer.readout import unique_rows

GRAPH = SubgoalGraph(["a1", "b1", "a2", "b2"], [("a1", "b1", 1), ("a2", "b2", 1), ("a1", "a2", -1)])


def _critic(theta=(2.0, 2.0, -1.0, -1.0), seed=0, **cfg):
    c = SubgoalCritic(GRAPH, config=InferenceConfig(num_samples=64, burn_in=8, **cfg), seed=seed)
    sd = c.state_dict()
    sd["theta"] = torch.tensor(theta)
    c.load_state_dict(sd)
    return c


def test_unique_rows_is_torch_unique_in_the_same_order():
    g = torch.Generator().manual_seed(0)
    w = (torch.rand(200, 6, generator=g) > 0.5).float()
    configs, counts = unique_rows(w)
    ref_configs, ref_counts = torch.unique(w, dim=0, return_counts=True)
    assert torch.equal(configs, ref_configs) and torch.equal(counts, ref_counts)
    assert int(counts.sum()) == 200


def test_filtered_set_is_the_mode_of_the_samples_that_agree_with_the_given():
    critic = _critic()
    samples = torch.tensor([[1, 1, 0, 0]] * 5 + [[0, 0, 1, 1]] * 3 + [[1, 0, 1, 0]] * 2, dtype=torch.float32)
    critic._last_samples = samples
    assert critic.filtered_set().tolist() == [True, True, False, False]
    given = torch.tensor([[False, False, True, False],      # holds a2: the mode among rows with a2
                          [False, True, False, True]])      # nothing agrees: the unconditional mode
    assert critic.filtered_set(given=given).tolist() == [[False, False, True, True], [True, True, False, False]]
    assert critic.filtered_set(given=given[0]).tolist() == [False, False, True, True]
    with pytest.raises(ValueError, match=r"given must have shape \(4,\) or \(B, 4\)"):
        critic.filtered_set(given=torch.zeros(3, dtype=torch.bool))


def test_complete_missing_gives_rows_no_sample_agrees_with_their_completion_and_leaves_the_rest():
    critic = _critic()
    critic._last_samples = torch.tensor([[1, 1, 0, 0]] * 5 + [[0, 0, 1, 1]] * 3, dtype=torch.float32)
    given = torch.tensor([[False, False, True, False],      # a sample agrees: the mode among those
                          [False, True, False, True]])      # none does: q's completion of the row
    out = critic.filtered_set(given=given, complete_missing=True)
    assert out[0].tolist() == [False, False, True, True]
    assert out[1].tolist() == critic.completion(given[1]).tolist()
    assert out[1].tolist() != [True, True, False, False]     # not the unconditional mode: b2 is held
    assert bool(out[1][1]) and bool(out[1][3])


def test_filtered_set_given_every_possible_row_matches_a_brute_force_count():
    critic = _critic()
    g = torch.Generator().manual_seed(3)
    samples = (torch.rand(200, 4, generator=g) < torch.tensor([0.7, 0.6, 0.3, 0.2])).float()
    samples[:, 3] *= 1.0 - samples[:, 2]             # no sample holds both b's: those rows get the mode
    critic._last_samples = samples
    given = state_table(4).bool()                                    # all 16 achieved sets at once

    def brute(row):
        counts = {}
        for w in samples.tolist():
            if all(w[i] == 1.0 for i in range(4) if row[i]):
                counts[tuple(w)] = counts.get(tuple(w), 0) + 1
        if not counts:
            return None
        best = max(counts.values())
        return list(min(c for c, k in counts.items() if k == best))      # ties: lexicographically smallest

    mode = critic.filtered_set().float().tolist()
    expected = [brute(row.tolist()) or mode for row in given]
    assert critic.filtered_set(given=given).float().tolist() == expected
    assert any(e != mode for e in expected) and any(brute(r.tolist()) is None for r in given)


def test_ranking_puts_the_most_probable_configuration_first_with_its_exact_probability():
    critic = _critic(theta=(3.0, 3.0, -3.0, -3.0))
    top = critic.ranking(num_samples=3000, top_k=3)
    assert top[0]["subgoals"] == ["a1", "b1"] and top[0]["mask"] == [1, 1, 0, 0]
    assert [r["prob"] for r in top] == sorted((r["prob"] for r in top), reverse=True)
    exact = critic.log_q(torch.tensor([1.0, 1.0, 0.0, 0.0])).exp().item()
    assert top[0]["exact_prob"] == pytest.approx(exact, rel=1e-5)
    assert abs(top[0]["prob"] - exact) < 5 * (exact * (1 - exact) / 3000) ** 0.5
    assert torch.logsumexp(critic.log_q(state_table(4)), 0).item() == pytest.approx(0.0, abs=1e-5)
    with pytest.raises(ValueError, match="need num_samples >= 1 and top_k >= 1"):
        critic.ranking(num_samples=0)


def test_marginals_above_the_exact_limit_are_the_last_samples_mean():
    critic = _critic(exact_max_n=2)
    with pytest.raises(RuntimeError, match="no update has run yet"):
        critic.last_samples()
    critic._last_samples = torch.tensor([[1.0, 0, 0, 1], [1.0, 1, 0, 0]])
    assert critic.marginals().tolist() == [1.0, 0.5, 0.0, 0.5]
    exact = _critic().marginals()
    assert torch.allclose(exact, (critic.log_q(state_table(4)).exp()[:, None] * state_table(4)).sum(0), atol=1e-5)


def _local_maxima(c, given):
    """Every configuration holding ``given`` that no single flip of a free site improves under log q,
    by enumeration of the 2^N states (log q's differences are exact: log Z cancels)."""
    states = state_table(c.n).float()
    lq = c.log_q(states)
    code = {tuple(s.int().tolist()): float(v) for s, v in zip(states, lq)}
    out = []
    for s in states:
        if not bool((s.bool() | ~given).all()):
            continue
        key = tuple(s.int().tolist())
        flips = [tuple(1 - b if j == i else b for j, b in enumerate(key)) for i in range(c.n) if not given[i]]
        if all(code[f] <= code[key] + 1e-6 for f in flips):
            out.append(key)
    return out, code


@pytest.mark.parametrize("seed", range(6))
def test_completion_is_a_local_maximum_of_q_given_the_achieved(seed):
    g = torch.Generator().manual_seed(seed)
    n = 7
    edges = [(f"s{u}", f"s{v}", 1 if torch.rand(1, generator=g) > 0.3 else -1)
             for u in range(n) for v in range(u + 1, n) if torch.rand(1, generator=g) < 0.4]
    c = SubgoalCritic(SubgoalGraph([f"s{i}" for i in range(n)], edges), seed=seed)
    sd = c.state_dict()
    sd["theta"] = torch.randn(n, generator=g) * 2
    sd["coupling"] = (torch.rand(len(edges), generator=g) * 4) * torch.tensor([float(s) for *_, s in edges])
    c.load_state_dict(sd)
    given = torch.rand(4, n, generator=g) < 0.2
    comp = c.completion(given)
    assert comp.shape == given.shape and comp.dtype == torch.bool
    assert bool((comp | ~given).all())                               # the given stay on
    for row, out in zip(given, comp):
        maxima, code = _local_maxima(c, row)
        assert tuple(out.int().tolist()) in maxima
    assert c.completion(given[0]).tolist() == comp[0].tolist()       # (N,) in, (N,) out


def _random_critic(seed, n=7):
    g = torch.Generator().manual_seed(seed)
    edges = [(f"s{u}", f"s{v}", 1 if torch.rand(1, generator=g) > 0.3 else -1)
             for u in range(n) for v in range(u + 1, n) if torch.rand(1, generator=g) < 0.4]
    c = SubgoalCritic(SubgoalGraph([f"s{i}" for i in range(n)], edges),
                      config=InferenceConfig(num_samples=16, burn_in=4), seed=seed)
    sd = c.state_dict()
    sd["theta"] = torch.randn(n, generator=g) * 2
    sd["coupling"] = (torch.rand(len(edges), generator=g) * 4) * torch.tensor([float(s) for *_, s in edges])
    c.load_state_dict(sd)
    return c, g


def test_completion_of_a_key_door_prior_is_the_route_of_the_key_held():
    graph = SubgoalGraph(["yk", "yd", "bk", "bd", "goal"] + [f"x{i}" for i in range(6)],
                         [("yk", "yd", 1), ("bk", "bd", 1), ("yk", "bk", -1), ("yd", "bd", -1),
                          ("yd", "goal", 1), ("bd", "goal", 1)])
    c = SubgoalCritic(graph, prior="ising", prior_params={"strength": 3.0, "field": -2.0},
                      config=InferenceConfig(init="prior"), seed=0)
    names = list(graph.names)

    def complete(*held):
        mask = c.completion(torch.tensor([nm in held for nm in names]))
        return {nm for nm, m in zip(names, mask.tolist()) if m}

    assert complete() == set()                          # holding nothing: every flip lowers log q
    assert complete("bk") == {"bk", "bd", "goal"}
    assert complete("yk") == {"yk", "yd", "goal"}
    assert complete("yk", "bd") == {"yk", "yd", "bd", "goal"}   # the given stay on even against an edge
    with pytest.raises(ValueError, match="given must have shape"):
        c.completion(torch.zeros(3, dtype=torch.bool))
