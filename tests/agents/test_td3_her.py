"""GoalTD3 + HER: relabelling and rewards on constructed trajectories, action bounds, exact resume,
and a tiny run on a point mass (written here) that must learn to reach its targets."""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.td3_her import GoalTD3, GoalTD3Config, goal_reward, her_future_relabel


class PointMass(gym.Env):
    """A 2-d point in [-1, 1]^2 moved by 0.1 * action[:2]; action[2] is a gripper command.

    Sub-goal i is "go to target i with gripper command grip[i]"; targets are redrawn every reset.
    """

    def __init__(self, n_targets: int = 2):
        self.action_space = gym.spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.subgoal_names = [f"target_{i}" for i in range(n_targets)]
        self.grip = np.array([(-1.0) ** i for i in range(n_targets)])
        self.pos = np.zeros(2)
        self.targets = np.zeros((n_targets, 2))

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = self.np_random.uniform(-0.8, 0.8, 2)
        self.targets = self.np_random.uniform(-0.8, 0.8, (len(self.subgoal_names), 2))
        return self.pos.astype(np.float32), {}

    def step(self, action):
        self.pos = np.clip(self.pos + 0.1 * np.asarray(action[:2], dtype=np.float64), -1.0, 1.0)
        return self.pos.astype(np.float32), 0.0, False, False, {}

    def subgoal_target(self, i):
        return self.targets[i], float(self.grip[i])


@pytest.fixture(autouse=True)
def one_thread():
    # small nets: one thread is fastest on a shared 2-core machine (threads contend otherwise)
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def make_agent(seed: int = 0, **overrides) -> GoalTD3:
    cfg = GoalTD3Config(**{"hidden": (64, 64), "batch_size": 64, "learning_starts": 200, "gamma": 0.9,
                           "tolerance": 0.1, "goal_scale": 1.0, "use_obs": False, **overrides})
    return GoalTD3(2, -np.ones(3), np.ones(3), (0, 2), 2, cfg, torch.Generator().manual_seed(seed),
                   np.random.default_rng(seed))


def run_episode(agent: GoalTD3, env: PointMass, seed: int, steps: int, explore: float, train: bool = True):
    obs, _ = env.reset(seed=seed)
    g = seed % len(env.subgoal_names)
    agent.begin_option()
    for _ in range(steps):
        a = agent.act(obs, g, explore, env)
        nxt, *_ = env.step(a)
        if train:
            agent.observe(obs, a, nxt, None, None, False)
        obs = nxt
    target, grip = env.subgoal_target(g)
    return np.linalg.norm(env.pos - target) < 0.1 and abs(a[2] - grip) < 0.5


# ---------------------------------------------------------------- HER relabelling and rewards
def test_goal_reward_is_zero_inside_the_region_and_minus_one_outside():
    pos = np.array([[0.0, 0.0, 0.0], [0.015, 0.0, 0.0], [0.025, 0.0, 0.0], [0.0, 0.0, 0.0]])
    grip = np.array([1.0, 1.0, 1.0, -1.0])
    r = goal_reward(pos, grip, np.zeros((4, 3)), np.ones(4), tolerance=0.02, gripper_tolerance=0.5)
    np.testing.assert_array_equal(r, [0.0, 0.0, -1.0, -1.0])   # too far; wrong gripper command
    np.testing.assert_array_equal(goal_reward(pos, None, np.zeros((4, 3)), None, 0.02, 0.5), [0, 0, -1, 0])


def test_future_relabelling_draws_only_from_the_same_or_later_steps_uniformly():
    T, k = 5, 4000
    achieved = np.arange(T, dtype=np.float32)[:, None] * 10.0    # achieved[t] identifies t
    source, goals = her_future_relabel(achieved, k, np.random.default_rng(0))
    assert source.shape == (T * k,) and goals.shape == (T * k, 1)
    future = (goals[:, 0] / 10.0).astype(int)
    assert (future >= source).all() and (future < T).all()
    for t in range(T):    # uniform over {t, ..., T-1}: 4000 draws, 5 sigma binomial tolerance
        counts = np.bincount(future[source == t], minlength=T)[t:]
        p = 1.0 / (T - t)
        tol = 5 * np.sqrt(k * p * (1 - p)) + 1e-9
        assert np.all(np.abs(counts - k * p) <= tol), (t, counts)
    assert her_future_relabel(achieved[:0], 4, np.random.default_rng(0))[0].size == 0


def test_end_trajectory_stores_originals_and_relabelled_copies_with_the_right_rewards():
    agent = make_agent(her_k=2)
    env = PointMass()
    env.reset(seed=1)
    env.targets[0] = [0.5, 0.5]
    obs = [np.array([0.0, 0.0]), np.array([0.1, 0.0]), np.array([0.2, 0.0]), np.array([0.5, 0.45])]
    acts = [np.array([1.0, 0.0, 1.0]), np.array([1.0, 0.0, -1.0]), np.array([1.0, 1.0, 1.0])]
    agent.begin_option()
    for t in range(3):
        agent.act(obs[t], 0, 0.0, env)               # records goal (0.5, 0.5, grip +1)
        agent.observe(obs[t], acts[t], obs[t + 1], None, None, False)
    assert len(agent.buffer) == 0                     # buffered until the trajectory ends
    assert agent.end_trajectory() == 3 * (1 + 2)
    d = agent.buffer.data
    n = len(agent.buffer)
    # originals: goal (0.5, 0.5, +1); only the last step ends within 0.1 with the gripper at +1
    np.testing.assert_allclose(d["goal"][:3], np.tile([0.5, 0.5, 1.0], (3, 1)))
    np.testing.assert_array_equal(d["reward"][:3], [-1.0, -1.0, 0.0])
    achieved = np.array([[0.1, 0.0, 1.0], [0.2, 0.0, -1.0], [0.5, 0.45, 1.0]])
    for i in range(3, n):
        src = int(np.flatnonzero(np.isclose(d["obs"][i], np.stack(obs[:3])).all(1))[0])
        np.testing.assert_allclose(d["action"][i], acts[src])
        # the goal is what some step t' >= src achieved, and the reward says whether src reached it
        match = np.flatnonzero(np.isclose(achieved, d["goal"][i]).all(1))
        assert match.size == 1 and match[0] >= src
        reached = np.linalg.norm(achieved[src, :2] - d["goal"][i, :2]) < 0.1 and \
            abs(achieved[src, 2] - d["goal"][i, 2]) < 0.5
        assert d["reward"][i] == (0.0 if reached else -1.0)
    assert (d["reward"][3:n] == 0.0).sum() >= 2       # t' = t copies always succeed; some must exist


def test_observe_without_act_is_an_error():
    with pytest.raises(RuntimeError, match="observe\\(\\) before act\\(\\)"):
        make_agent().observe(np.zeros(2), np.zeros(3), np.zeros(2), None, None, False)


def test_bad_settings_are_rejected_by_name():
    with pytest.raises(ValueError, match=r"gamma\n.*less than 1"):      # pydantic's error, built in Python
        GoalTD3Config(gamma=1.5)
    env = PointMass()
    with pytest.raises(ValueError, match=r"unknown key 'lr' in section 'low'; valid keys: .*actor_lr"):
        GoalTD3.for_env(env, {"lr": 1e-3}, torch.Generator(), np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"^low.gamma takes a number in \[0, 1\) \(default 0.95\), got 1.5$"):
        GoalTD3.for_env(env, {"gamma": 1.5}, torch.Generator(), np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"low.her_k takes an integer"):
        GoalTD3.for_env(env, {"her_k": "many"}, torch.Generator(), np.random.default_rng(0))
    with pytest.raises(ValueError, match="robot0_eef_pos"):
        GoalTD3.for_env(env, {}, torch.Generator(), np.random.default_rng(0))


# ---------------------------------------------------------------- acting
def test_actions_respect_the_bounds_and_greedy_actions_are_deterministic():
    low, high = np.array([-0.5, -2.0, 0.0]), np.array([0.5, 1.0, 3.0])
    agent = GoalTD3(2, low, high, (0, 2), 2, GoalTD3Config(hidden=(16,), noise_sigma=5.0),
                    torch.Generator().manual_seed(0), np.random.default_rng(0))
    env = PointMass()
    env.reset(seed=0)
    acts = np.stack([agent.act(np.random.default_rng(i).uniform(-1, 1, 2).astype(np.float32), 0, 1.0, env)
                     for i in range(300)])
    assert acts.dtype == np.float32 and (acts >= low - 1e-6).all() and (acts <= high + 1e-6).all()
    move = slice(0, 2)                   # the motion; the gripper is the target's command, clipped to its bounds
    assert (acts.min(0)[move] < low[move] + 0.05).all() and (acts.max(0)[move] > high[move] - 0.05).all()
    assert (acts[:, 2] == 1.0).all()     # sub-goal 0 commands +1
    obs = np.array([0.3, -0.2], np.float32)
    np.testing.assert_array_equal(agent.act(obs, 1, 0.0, env), agent.act(obs, 1, 0.0, env))


# ---------------------------------------------------------------- checkpointing
def test_state_dict_round_trip_continues_identically():
    env_a, env_b = PointMass(), PointMass()
    a = make_agent(seed=3, learning_starts=64)
    for ep in range(6):
        run_episode(a, env_a, ep, 15, 0.5)
    b = make_agent(seed=99, learning_starts=64)       # different init, overwritten by the checkpoint
    b.load_state_dict(copy.deepcopy(a.state_dict()))
    b.rng.bit_generator.state = a.rng.bit_generator.state   # the loop checkpoints rng separately
    for ep in range(6, 9):
        run_episode(a, env_a, ep, 15, 0.5)
        run_episode(b, env_b, ep, 15, 0.5)
    for (ka, va), (kb, vb) in zip(a.actor.state_dict().items(), b.actor.state_dict().items()):
        assert ka == kb and torch.equal(va, vb)
    assert a.updates == b.updates > 0
    np.testing.assert_array_equal(a.buffer.data["goal"], b.buffer.data["goal"])


# ---------------------------------------------------------------- learning
def test_learns_to_reach_point_mass_targets():
    env = PointMass()
    agent = make_agent(seed=0)
    before = np.mean([run_episode(agent, env, 10_000 + i, 25, 0.0, train=False) for i in range(40)])
    for ep in range(64):                       # 1,600 env steps (1,400 TD3 updates)
        run_episode(agent, env, ep, 25, 0.5)
    after = np.mean([run_episode(agent, env, 10_000 + i, 25, 0.0, train=False) for i in range(40)])
    assert before < 0.3
    assert after >= 0.85, f"greedy reach success {after:.2f} after 1,600 steps (was {before:.2f})"


def test_observation_normaliser_matches_numpy_over_batches_and_round_trips():
    from hubsgo_ppl.agents.td3_her import ObsNormaliser

    x = np.random.default_rng(0).normal([1.0, -3.0, 0.8], [0.5, 2.0, 1e-4], size=(300, 3))
    norm = ObsNormaliser(3, clip=5.0)
    np.testing.assert_array_equal(norm(torch.full((3,), 0.02)).numpy(), [2.0, 2.0, 2.0])   # no data: std floor
    for chunk in np.array_split(x, 7):          # unequal batches: the parallel update must be exact
        norm.update(chunk)
    assert norm.count == 300
    np.testing.assert_allclose(norm.mean, x.mean(0), rtol=1e-12)
    np.testing.assert_allclose(norm.std, x.std(0), rtol=1e-10)
    z = norm(torch.as_tensor(x, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(z[:, :2].mean(0), 0.0, atol=1e-4)
    assert np.abs(z).max() <= 5.0                # clipped; the 1e-2 std floor keeps feature 3 finite
    other = ObsNormaliser(3, clip=5.0)
    other.load_state_dict(norm.state_dict())
    np.testing.assert_array_equal(other(torch.ones(3)).numpy(), norm(torch.ones(3)).numpy())
    # a checkpoint of the earlier layout (sum of squared deviations "m2") loads to the same statistics
    legacy = ObsNormaliser(3, clip=5.0)
    legacy.load_state_dict({"count": 300.0, "mean": norm.mean.copy(), "m2": norm.std ** 2 * 300})
    np.testing.assert_allclose(legacy.std, norm.std, rtol=1e-12)
    agent = make_agent(use_obs=True)             # the obs-fed variant builds and acts
    env = PointMass()
    env.reset(seed=0)
    assert agent.act(np.zeros(2, np.float32), 0, 0.0, env).shape == (3,)


def test_the_gripper_command_is_the_targets_also_when_exploring():
    """Exploration moves the hand at random but never opens a hand that carries an object."""
    env = PointMass(n_targets=2)
    agent = make_agent(3)
    obs, _ = env.reset(seed=3)
    for g in (0, 1):
        _, grip = env.subgoal_target(g)
        actions = np.stack([agent.act(obs, g, 1.0, env) for _ in range(200)])
        assert (actions[:, 2] == grip).all() and actions[:, :2].std(0).min() > 0.1
        assert agent.act(obs, g, 0.0, env)[2] == grip
