"""SB3 baselines behind the trainer protocol: every flat agent on every grid task, exact resume, DDQN target."""

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from stable_baselines3 import DQN

from hubsgo_ppl.agents.flat import DoubleDQN, SB3Trainer, build_ddqn, build_dqn, build_ppo
from hubsgo_ppl.agents.presets import preset
from hubsgo_ppl.envs import make, register
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, evaluate, load_run, train

GRID_TASKS = ["keydoor", "fourroom", "keydoor_incorrect", "fourroom_incorrect"]
TINY = {"dqn": ["dqn.learning_starts=200", "dqn.batch_size=32", "dqn.buffer_size=5000",
                "dqn.policy_kwargs.net_arch=[32]", "dqn.target_update_interval=100"],
        "ddqn": ["dqn.learning_starts=200", "dqn.batch_size=32", "dqn.buffer_size=5000",
                 "dqn.policy_kwargs.net_arch=[32]", "dqn.target_update_interval=100"],
        "ppo": ["ppo.n_steps=256", "ppo.batch_size=64", "ppo.n_epochs=2", "ppo.policy_kwargs.net_arch=[32]"]}


def _rows(path):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in read_csv_rows(path / "metrics.csv")]


@pytest.mark.parametrize("task", GRID_TASKS)
@pytest.mark.parametrize("agent", ["dqn", "ddqn", "ppo"])
def test_every_flat_agent_trains_on_every_grid_task(tmp_path, agent, task):
    out = tmp_path / "run"
    summary = train(RunConfig(task=task, agent=agent, steps=1, seed=0, overrides=TINY[agent]), out, progress=False)
    assert summary["finished"]
    rows = read_csv_rows(out / "metrics.csv")
    assert [int(r["episode"]) for r in rows] == list(range(summary["episodes"])) and rows
    env = make(task)
    max_steps = env.unwrapped.max_steps
    env.close()
    for r in rows:
        assert int(r["options"]) == 1 and float(r["filter_eps"]) == 0.0
        length, ret, success = int(r["length"]), float(r["return"]), int(r["success"])
        assert 1 <= length <= max_steps
        # MiniGrid's reward: 1 - 0.9 * steps / max_steps on reaching the goal, 0 otherwise
        assert ret == pytest.approx(1 - 0.9 * length / max_steps if success else 0.0, abs=1e-12)
    steps = [int(r["env_steps"]) for r in rows]
    assert steps == sorted(steps) and steps[-1] <= summary["env_steps"]
    if agent != "ppo":     # the whole run is past exploration_fraction, so ε is at its floor
        assert float(rows[-1]["explore_eps"]) == pytest.approx(0.05)
    result = evaluate(out, episodes=1)
    assert result["agent"] == agent and result["episodes"] == 1


@pytest.mark.parametrize("agent", ["ddqn", "ppo"])
def test_resume_after_crash_continues_exactly(tmp_path, agent):
    """A chunk usually ends mid-episode; resume replays the open episode, so metrics match exactly."""
    def cfg():
        return RunConfig(task="fourroom", agent=agent, steps=2500, seed=5, checkpoint_steps=1,
                         overrides=TINY[agent])

    full = tmp_path / "full"
    train(cfg(), full, progress=False)
    crashed = tmp_path / "crashed"

    class Crash(Exception):
        pass

    def crash(stats):
        if stats.episode == 1:
            raise Crash

    with pytest.raises(Crash):
        train(cfg(), crashed, progress=False, on_episode=crash)
    train(cfg(), crashed, resume=True, progress=False)
    assert len(_rows(full)) >= 3
    assert _rows(crashed) == _rows(full)


def _plain(x, where="state"):
    """Checkpoints hold tensors, arrays and plain data only (never SB3's pickled model objects)."""
    if isinstance(x, dict):
        for k, v in x.items():
            assert isinstance(k, (str, int)), f"{where}: key {k!r}"
            _plain(v, f"{where}.{k}")
    elif isinstance(x, (list, tuple)):
        for i, v in enumerate(x):
            _plain(v, f"{where}[{i}]")
    else:
        assert x is None or isinstance(x, (str, int, float, bool, np.ndarray, np.generic, torch.Tensor)), \
            f"{where} is a {type(x).__name__}"


@pytest.mark.parametrize("build", [build_dqn, build_ppo])
def test_state_dict_is_plain_data(build):
    register()
    cfg = preset("minigrid")
    cfg["steps"] = 300
    cfg["dqn"].update(learning_starts=50, batch_size=16, buffer_size=2000)
    cfg["ppo"].update(n_steps=128, batch_size=32)
    trainer = build(make("fourroom"), cfg, seed=1)
    trainer.train_chunk()
    _plain(trainer.state_dict())


def test_sb3_global_rngs_are_sandboxed():
    """Training draws from the trainer's own RNG states, not from (and without disturbing) the caller's."""
    register()
    cfg = preset("minigrid")
    cfg["steps"] = 600
    cfg["dqn"].update(learning_starts=50, batch_size=16, buffer_size=2000, policy_kwargs={"net_arch": [16]})
    outcomes = []
    for disturb in (False, True):
        np.random.seed(1234)
        torch.manual_seed(1234)
        outer = (np.random.get_state()[1].copy(), torch.get_rng_state().clone())
        trainer = build_ddqn(make("fourroom"), cfg, seed=2)
        if disturb:      # the caller's global RNG use between chunks must not change training
            np.random.rand(100)
            torch.rand(100)
        stats = trainer.train_chunk()
        if not disturb:
            assert np.array_equal(np.random.get_state()[1], outer[0])
            assert torch.equal(torch.get_rng_state(), outer[1])
        outcomes.append(([(s.ret, s.length) for s in stats], trainer.env_steps,
                         [p.detach().clone() for p in trainer.model.q_net.parameters()]))
    assert outcomes[0][:2] == outcomes[1][:2]
    assert all(torch.equal(a, b) for a, b in zip(outcomes[0][2], outcomes[1][2]))


def test_dqn_is_sb3_dqn_and_ddqn_uses_the_double_q_target():
    register()
    cfg = preset("minigrid")
    cfg["steps"] = 1000
    assert type(build_dqn(make("fourroom"), cfg, seed=0).model) is DQN
    trainer: SB3Trainer = build_ddqn(make("fourroom"), cfg, seed=0)
    model = trainer.model
    assert isinstance(model, DoubleDQN)
    gen = torch.Generator().manual_seed(0)
    with torch.no_grad():      # make target != online so the two targets differ
        for p in model.q_net_target.parameters():
            p.add_(torch.randn(p.shape, generator=gen) * 0.5)
    obs_dim = model.observation_space.shape[0]
    s, s2 = np.zeros((1, obs_dim), np.float32), np.zeros((1, obs_dim), np.float32)
    s[0, [1, 14, 26]] = 1
    s2[0, [2, 14, 26]] = 1
    model.replay_buffer.add(s, s2, np.array([[2]]), np.array([0.5]), np.array([False]), [{}])
    st, st2 = torch.as_tensor(s), torch.as_tensor(s2)
    with torch.no_grad():
        online_next, target_next = model.q_net(st2)[0], model.q_net_target(st2)[0]
        q_sa = model.q_net(st)[0, 2]
        double_y = 0.5 + model.gamma * target_next[online_next.argmax()]
        vanilla_y = 0.5 + model.gamma * target_next.max()
    assert online_next.argmax() != target_next.argmax(), "construction must separate the two targets"
    expected = float(F.smooth_l1_loss(q_sa, double_y))
    model.train(gradient_steps=1, batch_size=4)      # every sample is the single stored transition
    assert model.logger.name_to_value["train/loss"] == pytest.approx(expected, rel=1e-5)
    assert float(F.smooth_l1_loss(q_sa, vanilla_y)) != pytest.approx(expected, rel=1e-3)


def test_exploration_schedule_follows_the_run_budget_not_the_chunk():
    register()
    cfg = preset("minigrid")
    cfg["steps"] = 100_000
    cfg["dqn"].update(learning_starts=10_000, buffer_size=5000, policy_kwargs={"net_arch": [16]})
    trainer = build_dqn(make("fourroom"), cfg, seed=0)
    stats = trainer.train_chunk()
    progress = trainer.env_steps / 100_000
    assert trainer.env_steps < 5000
    assert stats[-1].explore_eps == pytest.approx(1 - 0.95 * progress / 0.3, abs=1e-6)


def test_bad_settings_are_named():
    register()
    cfg = preset("minigrid")
    cfg["steps"] = 100
    cfg["ppo"]["learning_rate"] = "lin_3e-4"
    with pytest.raises(ValueError, match="ppo.learning_rate"):
        build_ppo(make("fourroom"), cfg, seed=0)
    cfg = preset("minigrid")
    cfg["dqn"]["not_a_setting"] = 1
    with pytest.raises(ValueError, match="bad dqn setting"):
        build_dqn(make("fourroom"), cfg, seed=0)


@pytest.mark.mujoco
def test_td3_trains_on_an_arm_task(tmp_path):
    out = tmp_path / "td3"
    summary = train(RunConfig(task="stack_cubes", agent="td3", steps=1, seed=0,
                              overrides=["td3.learning_starts=350", "td3.batch_size=32",
                                         "td3.policy_kwargs.net_arch=[32]"]), out, progress=False)
    rows = read_csv_rows(out / "metrics.csv")
    assert summary["finished"] and len(rows) == 1
    # sparse reward 1 exactly on success, which ends the episode; otherwise it runs to the horizon
    length, success = int(rows[0]["length"]), int(rows[0]["success"])
    assert float(rows[0]["return"]) == float(success)
    _, env, _, _ = load_run(out)
    horizon = env.unwrapped.horizon
    env.close()
    assert int(rows[0]["env_steps"]) == length and (success or length == horizon)
    assert "train/critic_loss" in rows[0] and math.isfinite(float(rows[0]["train/critic_loss"]))
    assert float(rows[0]["explore_eps"]) == pytest.approx(0.1)


@pytest.mark.mujoco
def test_ppo_trains_on_an_arm_task_with_the_family_s_own_settings(tmp_path):
    from hubsgo_ppl.experiments.checkpoint import run_config

    out = tmp_path / "ppo"
    summary = train(RunConfig(task="push_any_one", agent="ppo", steps=1, seed=0,
                              overrides=["ppo.n_steps=128", "ppo.policy_kwargs.net_arch=[32]"]), out, progress=False)
    rows = read_csv_rows(out / "metrics.csv")
    assert summary["finished"] and rows and float(rows[0]["return"]) == float(rows[0]["success"])
    hyper = run_config(out)["hyper"]["ppo"]
    assert hyper["n_epochs"] == 10 and hyper["n_steps"] == 128      # the family's preset, --set over it
