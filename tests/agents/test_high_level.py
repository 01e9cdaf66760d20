import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.high_level import HighLevelBatch, HighLevelConfig, HighLevelDQN, linked_rows, masked_max


def test_masked_max_matches_python_reference_and_empty_is_zero():
    g = torch.Generator().manual_seed(0)
    values = torch.randn(7, 5, generator=g)
    mask = torch.rand(7, 5, generator=g) > 0.5
    mask[3] = False
    got = masked_max(values, mask)
    for i in range(7):
        picked = [values[i, j].item() for j in range(5) if mask[i, j]]
        assert got[i].item() == pytest.approx(max(picked) if picked else 0.0)


def test_residuals_equal_eq2_per_configuration_and_keep_grad_path():
    g = torch.Generator().manual_seed(1)
    B, N = 6, 4
    batch = HighLevelBatch(q_taken=torch.randn(B, generator=g), q_next=torch.randn(B, N, generator=g),
                           reward=torch.rand(B, generator=g), discount=torch.full((B,), 0.9),
                           available=torch.rand(B, N, generator=g) > 0.2)
    w = torch.tensor([[1.0, 0, 1, 0], [0, 0, 0, 0], [1, 1, 1, 1]])
    res = batch.residuals(w)
    assert res.shape == (3, B)
    for s in range(3):
        for b in range(B):
            allowed = [batch.q_next[b, j].item() for j in range(N) if w[s, j] > 0 and batch.available[b, j]]
            y = batch.reward[b].item() + 0.9 * (max(allowed) if allowed else 0.0)
            assert res[s, b].item() == pytest.approx(y - batch.q_taken[b].item(), abs=1e-6)


def test_select_respects_allowed_set_and_is_seeded():
    def make():
        gen = torch.Generator().manual_seed(3)
        return HighLevelDQN(5, 4, HighLevelConfig(), gen, np.random.default_rng(3))

    a, b = make(), make()
    obs = np.ones(5, dtype=np.float32)
    allowed = np.array([False, True, False, True])
    picks_a = [a.select(obs, allowed, 0.5) for _ in range(50)]
    picks_b = [b.select(obs, allowed, 0.5) for _ in range(50)]
    assert picks_a == picks_b
    assert set(picks_a) <= {1, 3}
    with pytest.raises(ValueError, match="empty allowed set"):
        a.select(obs, np.zeros(4, dtype=bool), 0.0)


def test_update_reduces_td_loss_on_a_fixed_problem():
    gen = torch.Generator().manual_seed(0)
    rng = np.random.default_rng(0)
    dqn = HighLevelDQN(3, 2, HighLevelConfig(batch_size=16, learning_starts=16, lr=1e-2), gen, rng)
    for i in range(64):
        s = np.eye(3, dtype=np.float32)[i % 3]
        dqn.store(s, i % 2, float(i % 2), s, 0.0, np.array([True, True]))
    first = dqn.update(None)[0]["high/td_loss"]
    for _ in range(200):
        last = dqn.update(None)[0]["high/td_loss"]
    assert last < 0.1 * first


def _rows_of_flags(n: int, width: int = 3):
    """A stand-in for an env's subgoal_features: obs (..., n + width) -> rows whose column 0 is the
    sub-goal's own flag (obs[..., i]) and the rest the shared tail."""
    def feat(obs):
        flags = obs[..., :n].unsqueeze(-1)
        tail = obs[..., n:].unsqueeze(-2).expand(*obs.shape[:-1], n, width)
        return torch.cat([flags, tail], -1)

    feat.dim, feat.flag = 1 + width, 0
    return feat


def test_linked_rows_add_whether_a_positive_and_a_negative_neighbour_is_achieved():
    n = 5
    edges = [(0, 1, 1), (2, 3, 1), (0, 2, -1), (1, 3, -1), (3, 4, 1), (1, 4, 0)]      # the 0 edge links nothing
    pos = {0: {1}, 1: {0}, 2: {3}, 3: {2, 4}, 4: {3}}
    neg = {0: {2}, 1: {3}, 2: {0}, 3: {1}, 4: set()}
    feat = linked_rows(_rows_of_flags(n), n, edges)
    assert feat.dim == 1 + 3 + 2
    for bits in range(2 ** n):
        flags = [float((bits >> i) & 1) for i in range(n)]
        obs = torch.tensor(flags + [0.5, -1.0, 2.0])
        rows = feat(obs)
        assert rows.shape == (n, feat.dim)
        for i in range(n):
            assert rows[i, :4].tolist() == [flags[i], 0.5, -1.0, 2.0]
            assert rows[i, 4].item() == float(any(flags[j] for j in pos[i]))
            assert rows[i, 5].item() == float(any(flags[j] for j in neg[i]))
    batch = torch.rand(7, n + 3) > 0.5
    np.testing.assert_array_equal(feat(batch.float()).numpy(), torch.stack([feat(o.float()) for o in batch]).numpy())
    assert not linked_rows(_rows_of_flags(n), n, [])(torch.ones(n + 3))[:, 4:].any()


def test_a_high_level_over_rows_values_each_subgoal_by_its_own_row_only():
    n = 4
    feat = linked_rows(_rows_of_flags(n), n, [(0, 1, 1), (2, 3, -1)])
    high = HighLevelDQN(n + 3, n, HighLevelConfig(hidden=(16,), goal_features=True), torch.Generator().manual_seed(0),
                        np.random.default_rng(0), features=feat)
    assert high.q[-1].out_features == 1                 # one value per row, no output per sub-goal
    obs = np.array([1.0, 0.0, 0.0, 1.0, 0.3, -0.2, 0.7], np.float32)
    q = high.q_values(obs)
    rows = feat(torch.as_tensor(obs))
    with torch.no_grad():
        np.testing.assert_allclose(q, [high.q(rows[i]).item() for i in range(n)], rtol=1e-6)
    # sub-goals whose rows are equal get equal values, whatever their place in the catalogue
    same = np.array([0.0, 0.0, 0.0, 0.0, 0.3, -0.2, 0.7], np.float32)
    assert np.unique(high.q_values(same)).size == 1
    for _ in range(80):                                 # and the TD step runs through the rows
        high.store(obs, 1, 1.0, same, 0.9, np.ones(n, bool))
    stats, batch = high.update(None)
    assert np.isfinite(stats["high/td_loss"]) and batch.q_next.shape == (64, n)
    plain = HighLevelDQN(n + 3, n, HighLevelConfig(hidden=(16,)), torch.Generator().manual_seed(0),
                         np.random.default_rng(0), features=feat)
    assert plain.features is None and plain.q[-1].out_features == n     # the option off: one output each
