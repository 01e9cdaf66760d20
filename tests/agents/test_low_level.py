"""Low levels: GoalDQN's all-goal TD update against a hand computation, its ε-greedy act and update
cadence; ScriptedLowLevel's delegation to its controller."""

import copy

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.low_level import GoalDQN, GoalDQNConfig, ScriptedLowLevel


def _dqn(**kw):
    cfg = GoalDQNConfig(hidden=(8,), batch_size=1, learning_starts=1, train_every=1, gamma=0.9, **kw)
    return GoalDQN(3, 3, 2, cfg, torch.Generator().manual_seed(0), np.random.default_rng(0))


def test_update_is_the_all_goal_td_loss_computed_by_hand():
    low = _dqn()
    obs, nxt = np.array([0.1, 0.2, 0.3], np.float32), np.array([0.4, -0.1, 0.2], np.float32)
    before = np.array([True, False, False])      # goal 0 already held: no target, no loss
    after = np.array([True, True, False])        # goal 1 achieved by this step: reward 1, done
    q, q_target = copy.deepcopy(low.q), copy.deepcopy(low.q_target)
    diag = low.observe(obs, 1, nxt, before, after, False)           # batch of one: this transition
    with torch.no_grad():
        qa = q(torch.as_tensor(obs)).view(3, 2)[:, 1]
        q_next = q_target(torch.as_tensor(nxt)).view(3, 2).max(-1).values
    y = torch.tensor([0.0, 1.0, 0.0]) + 0.9 * torch.tensor([1.0, 0.0, 1.0]) * q_next    # goal 1 ends there
    expected = ((qa[1:] - y[1:]) ** 2).sum() / 2
    assert diag["low/td_loss"] == pytest.approx(float(expected), rel=1e-6)
    assert not torch.equal(next(low.q.parameters()), next(q.parameters()))              # it stepped


def test_goal_weights_scale_each_sub_goal_in_the_td_loss():
    low = _dqn()
    low.goal_weight = torch.tensor([5.0, 3.0, 0.5])
    obs, nxt = np.array([0.1, 0.2, 0.3], np.float32), np.array([0.4, -0.1, 0.2], np.float32)
    before, after = np.array([True, False, False]), np.array([True, True, False])
    q, q_target = copy.deepcopy(low.q), copy.deepcopy(low.q_target)
    diag = low.observe(obs, 1, nxt, before, after, False)
    with torch.no_grad():
        qa = q(torch.as_tensor(obs)).view(3, 2)[:, 1]
        q_next = q_target(torch.as_tensor(nxt)).view(3, 2).max(-1).values
    y = torch.tensor([0.0, 1.0, 0.0]) + 0.9 * torch.tensor([1.0, 0.0, 1.0]) * q_next
    # goal 0 is held (weight 0 whatever its goal weight); goals 1 and 2 weigh 3 and 0.5
    expected = (3.0 * (qa[1] - y[1]) ** 2 + 0.5 * (qa[2] - y[2]) ** 2) / 3.5
    assert diag["low/td_loss"] == pytest.approx(float(expected), rel=1e-6)
    other = _dqn()
    other.load_state_dict(low.state_dict())
    assert torch.equal(other.goal_weight, low.goal_weight)


def test_updates_start_after_learning_starts_and_follow_train_every():
    cfg = GoalDQNConfig(hidden=(8,), batch_size=2, learning_starts=3, train_every=2)
    low = GoalDQN(3, 2, 2, cfg, torch.Generator().manual_seed(0), np.random.default_rng(0))
    z, f = np.zeros(3, np.float32), np.zeros(2, bool)
    updated = [low.observe(z, 0, z, f, f, False) is not None for _ in range(7)]
    assert updated == [False, False, False, True, False, True, False]


def test_act_is_epsilon_greedy_on_the_goals_q():
    low = _dqn()
    obs = np.array([0.5, -0.5, 1.0], np.float32)
    with torch.no_grad():
        q = low.q(torch.as_tensor(obs)).view(3, 2)
    for g in range(3):
        assert low.act(obs, g, explore_eps=0.0) == int(q[g].argmax()) and not low.explored
    actions = {low.act(obs, 0, explore_eps=1.0) for _ in range(50)}
    assert low.explored and actions == {0, 1}


def test_state_dict_round_trip_and_shaping_needs_a_potential():
    low = _dqn()
    z, f = np.zeros(3, np.float32), np.zeros(3, bool)
    low.observe(z, 0, z, f, f, True)
    other = _dqn()
    other.load_state_dict(low.state_dict())
    assert other.steps == 1 and len(other.buffer) == 1
    assert all(torch.equal(a, b) for a, b in zip(low.q.parameters(), other.q.parameters()))
    with pytest.raises(ValueError, match="needs a potential"):
        _dqn(shaping=1.0)


def test_scripted_low_level_delegates_to_its_controller():
    calls = []

    class Controller:
        def act(self, env, goal):
            calls.append(("act", env, goal))
            return np.array([goal, 0.0])

        def reset(self):
            calls.append(("reset",))

    class Env:
        unwrapped = "the unwrapped env"

    low = ScriptedLowLevel(Controller())
    low.begin_option()
    assert low.act(None, 2, 0.5, Env()).tolist() == [2.0, 0.0]
    assert calls == [("reset",), ("act", "the unwrapped env", 2)]
    assert not low.learns
