import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.high_level import HighLevelBatch, HighLevelConfig, HighLevelDQN, masked_max


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
