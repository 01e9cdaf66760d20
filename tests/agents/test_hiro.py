"""HIRO: the off-policy correction on a constructed case, its pieces, and training on every task family."""

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.hiro import (GoalDQNLow, HIROConfig, build_hiro, candidate_goals, goal_sequence,
                                    off_policy_correction)
from hubsgo_ppl.agents.presets import preset
from hubsgo_ppl.envs import make, register
from hubsgo_ppl.experiments.io import load_checkpoint, save_torch
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, evaluate, train

GRID_TASKS = ["keydoor", "fourroom", "keydoor_incorrect", "fourroom_incorrect"]
TINY = ["hiro.hidden=[16]", "hiro.batch_size=8", "hiro.low_learning_starts=300", "hiro.high_learning_starts=8"]


def _rollout(goal, c, s0=(0.0, 0.0)):
    """A low level that plays a_i = g_i (its current relative goal); the state moves by a_i / 2."""
    s = np.array(s0, dtype=np.float64)
    g = np.array(goal, dtype=np.float64)
    states, actions = [s.copy()], []
    for _ in range(c):
        a = g.copy()
        s2 = s + 0.5 * a
        actions.append(a)
        g = s + g - s2                               # HIRO's goal transition h(s, g, s')
        s = s2
        states.append(s.copy())
    return np.array(states, np.float32), np.array(actions, np.float32)


def _log_lik(obs, goals, actions):                   # log N(a; μ(s, g) = g, I) up to a constant
    return -0.5 * (actions - goals).pow(2).sum(-1)


def test_correction_recovers_the_goal_that_generated_the_actions():
    c, true_goal = 4, np.array([4.0, 2.0], np.float32)
    states, actions = _rollout(true_goal, c)
    delta = states[-1] - states[0]                   # (3.75, 1.875): the achieved change
    cands = torch.as_tensor(np.array([[[-3.0, 1.0], delta, true_goal, [1.0, 1.0]]], np.float32))
    achieved = torch.as_tensor(states)[None]
    obs = achieved[:, :-1]
    acts = torch.as_tensor(actions)[None]
    goal, idx = off_policy_correction(_log_lik, obs, achieved, acts, torch.ones(1, c), cands)
    assert int(idx) == 2 and torch.allclose(goal[0], torch.as_tensor(true_goal))
    # the bug of public ports: scoring every step against the *initial* goal (no goal transition)
    # picks (1, 1), the candidate nearest the mean action, so this case tells the two apart
    naive = _log_lik(None, cands[0][:, None, :], acts[0][None]).sum(-1)
    assert int(naive.argmax()) == 3


def test_correction_is_per_transition_and_respects_the_mask():
    c = 4
    s_a, a_a = _rollout([4.0, 2.0], c)
    s_b, a_b = _rollout([-2.0, 3.0], 2)              # an episode that ended after 2 of c steps
    s_b = np.concatenate([s_b, np.repeat(s_b[-1:], 2, 0)])
    a_b = np.concatenate([a_b, np.full((2, 2), 99.0, np.float32)])   # padding must be ignored
    achieved = torch.as_tensor(np.stack([s_a, s_b]))
    acts = torch.as_tensor(np.stack([a_a, a_b]))
    mask = torch.tensor([[1.0, 1, 1, 1], [1, 1, 0, 0]])
    cands = torch.tensor([[[4.0, 2.0], [0.0, 0.0], [-2.0, 3.0]], [[4.0, 2.0], [0.0, 0.0], [-2.0, 3.0]]])
    goal, idx = off_policy_correction(_log_lik, achieved[:, :-1], achieved, acts, mask, cands)
    assert idx.tolist() == [0, 2]


def test_goal_sequence_matches_the_goal_transition():
    rng = np.random.default_rng(0)
    ag = rng.normal(size=(3, 6, 2)).astype(np.float32)
    g0 = rng.normal(size=(3, 5, 2)).astype(np.float32)
    seq = goal_sequence(torch.as_tensor(g0), torch.as_tensor(ag)).numpy()
    assert seq.shape == (3, 5, 5, 2)
    for b in range(3):
        for k in range(5):
            g = g0[b, k].copy()
            for i in range(5):
                np.testing.assert_allclose(seq[b, k, i], g, atol=1e-5)
                g = ag[b, i] + g - ag[b, i + 1]


def test_candidate_goals_original_achieved_and_gaussian_samples():
    rng = np.random.default_rng(1)
    B, n, scale = 4, 4000, np.array([5.0, 5.0], np.float32)
    orig = np.array([[9.0, -1.0]] * B, np.float32)
    ag = np.zeros((B, 3, 2), np.float32)
    ag[:, -1] = [1.0, -0.5]
    cands = candidate_goals(orig, ag, n, 0.5 * scale * 0.1, scale, rng)
    assert cands.shape == (B, n + 2, 2)
    np.testing.assert_allclose(cands[:, 0], [[5.0, -1.0]] * B)          # clipped to the goal range
    np.testing.assert_allclose(cands[:, 1], [[1.0, -0.5]] * B)
    samples = cands[:, 2:].reshape(-1, 2)
    np.testing.assert_allclose(samples.mean(0), [1.0, -0.5], atol=0.01)  # s.e. 0.25/sqrt(16000) = 0.002
    np.testing.assert_allclose(samples.std(0), [0.25, 0.25], rtol=0.03)
    wide = candidate_goals(orig, ag, 200, np.array([50.0, 50.0]), scale, rng)
    assert np.abs(wide).max() <= 5.0


def test_boltzmann_log_likelihood_is_a_normalised_softmax():
    cfg = HIROConfig(hidden=(8,), temperature=0.5)
    low = GoalDQNLow(6, np.array([3.0, 3.0], np.float32), 5, cfg, torch.Generator().manual_seed(0))
    obs, goal = torch.rand(7, 6), torch.rand(7, 2)
    ll = torch.stack([low.log_lik(obs, goal, torch.full((7,), a)) for a in range(5)], -1)
    torch.testing.assert_close(ll.exp().sum(-1), torch.ones(7))
    q = low.q(torch.cat([obs, goal / 3.0], -1))
    torch.testing.assert_close(ll, torch.log_softmax(q / 0.5, -1))


@pytest.mark.parametrize("task", GRID_TASKS)
def test_hiro_trains_on_every_grid_task(tmp_path, task):
    out = tmp_path / "hiro"
    summary = train(RunConfig(task=task, agent="hiro", steps=1, seed=0, overrides=TINY), out, progress=False)
    rows = read_csv_rows(out / "metrics.csv")
    assert summary["finished"] and len(rows) == 1
    r = rows[0]
    assert int(r["options"]) == -(-int(r["length"]) // 10)        # one goal per c = 10 steps
    # the episode's relabel rate is the fraction of replayed high-level transitions whose goal the
    # correction changed: the agent's own counts over this (only) episode's batches of 8
    replayed, changed = load_checkpoint(out / "checkpoint.pt")["agent"]["relabelled"]
    assert replayed == 8 * (int(r["options"]) - 7)      # one update per option from the 8th on
    assert float(r["high/relabel_rate"]) == pytest.approx(changed / replayed, rel=1e-12)
    if int(r["length"]) > 300:             # the low level learns once it holds 300 transitions
        assert np.isfinite(float(r["low/td_loss"]))
    assert evaluate(out, episodes=1)["episodes"] == 1


def test_hiro_state_dict_round_trip_continues_identically(tmp_path):
    register()
    cfg = preset("minigrid")
    cfg["steps"] = 10_000
    cfg["hiro"].update(hidden=[16], batch_size=8, low_learning_starts=500, high_learning_starts=8)
    a = build_hiro(make("fourroom"), cfg, seed=4)
    a.train_chunk()
    save_torch(tmp_path / "ckpt.pt", {"format": 1, "agent": a.state_dict()})
    next_a = a.train_chunk()[0]
    b = build_hiro(make("fourroom"), cfg, seed=4)
    b.load_state_dict(load_checkpoint(tmp_path / "ckpt.pt")["agent"])
    next_b = b.train_chunk()[0]
    assert next_a == next_b and next_a.episode == 1


def test_hiro_rejects_unknown_settings():
    register()
    cfg = preset("minigrid")
    cfg["hiro"]["horizon"] = 5
    with pytest.raises(ValueError, match=r"unknown key 'horizon' in section 'hiro'; valid keys: .*temperature"):
        build_hiro(make("fourroom"), cfg, seed=0)
    del cfg["hiro"]["horizon"]
    cfg["hiro"]["c"] = 0
    with pytest.raises(ValueError, match=r"^hiro.c takes an integer >= 1 \(default 10\), got 0$"):
        build_hiro(make("fourroom"), cfg, seed=0)


@pytest.mark.mujoco
def test_hiro_trains_on_an_arm_task(tmp_path):
    out = tmp_path / "hiro-arm"
    summary = train(RunConfig(task="stack_cubes", agent="hiro", steps=1, seed=0,
                              overrides=["hiro.hidden=[16]", "hiro.batch_size=8", "hiro.low_learning_starts=300",
                                         "hiro.high_learning_starts=8"]), out, progress=False)
    rows = read_csv_rows(out / "metrics.csv")
    assert summary["finished"] and len(rows) == 1
    assert np.isfinite(float(rows[0]["low/critic_loss"])) and np.isfinite(float(rows[0]["high/critic_loss"]))
