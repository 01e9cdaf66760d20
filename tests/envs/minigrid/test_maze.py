"""MazeEnv: Gymnasium compliance, seeded determinism, observations, rewards and the sub-goal contract."""

from __future__ import annotations

import textwrap
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX

from hubsgo_ppl.envs import get_task, make, register, tasks
from hubsgo_ppl.envs.minigrid import MazeEnv, bfs
from hubsgo_ppl.specs import SpecError

MINIGRID_TASKS = sorted(n for n, t in tasks().items() if t.family == "minigrid" and "layout" in t.catalogue.options)


def test_builtin_minigrid_tasks_present():
    assert {"keydoor", "fourroom", "keydoor_incorrect", "fourroom_incorrect"} <= set(MINIGRID_TASKS)


@pytest.mark.parametrize("task", MINIGRID_TASKS)
@pytest.mark.parametrize("obs_mode", ["symbolic", "image", "egocentric"])
def test_check_env(task, obs_mode):
    register()
    env = gym.make(get_task(task).env_id, obs_mode=obs_mode)
    with warnings.catch_warnings():
        warnings.simplefilter("error", category=UserWarning, append=False)
        # pygame's missing-font notice is not about our env
        warnings.filterwarnings("ignore", message=".*font.*")
        check_env(env.unwrapped, skip_render_check=True)
    obs, info = env.reset(seed=0)
    assert obs.dtype == np.float32 and obs.ndim == 1 and env.observation_space.contains(obs)


def _rollout(task: str, seed: int, n: int = 300):
    env = make(task)
    rng = np.random.default_rng(seed + 1000)
    obs, info = env.reset(seed=seed)
    trace = [(obs.copy(), 0.0, False, False, info["subgoals"].copy(), info["is_success"])]
    for _ in range(n):
        obs, r, te, tr, info = env.step(int(rng.integers(env.action_space.n)))
        trace.append((obs.copy(), r, te, tr, info["subgoals"].copy(), info["is_success"]))
        if te or tr:
            obs, info = env.reset()
            trace.append((obs.copy(), 0.0, False, False, info["subgoals"].copy(), info["is_success"]))
    return trace


def _same(a, b) -> bool:
    return len(a) == len(b) and all(
        np.array_equal(x[0], y[0]) and x[1:4] == y[1:4] and np.array_equal(x[4], y[4]) and x[5] == y[5]
        for x, y in zip(a, b))


@pytest.mark.parametrize("task", MINIGRID_TASKS)
def test_seeded_two_env_determinism(task):
    assert _same(_rollout(task, seed=7), _rollout(task, seed=7))


def test_seed_changes_only_what_the_catalogue_randomises():
    # fourroom draws its start direction (start_dir: random); keydoor fixes it (start_dir: right)
    fr = {int(np.argmax(make("fourroom", seed=s).unwrapped.gen_obs()[26:30])) for s in range(12)}
    assert fr == {0, 1, 2, 3}
    kd = [make("keydoor", seed=s).unwrapped.gen_obs() for s in range(5)]
    assert all(np.array_equal(kd[0], o) for o in kd)
    # episodes after the first keep drawing from the seeded generator
    env = make("fourroom", seed=0)
    dirs = [env.reset()[0][26:30].argmax() for _ in range(20)]
    env2 = make("fourroom", seed=0)
    assert dirs == [env2.reset()[0][26:30].argmax() for _ in range(20)] and len(set(dirs)) > 1


def test_symbolic_observation_layout():
    env = make("keydoor", seed=0)
    obs = env.unwrapped.gen_obs()
    assert obs.shape == (13 + 13 + 4 + 3 + 2,)
    assert obs[1] == 1 and obs[:13].sum() == 1                 # x = 1
    assert obs[13 + 6] == 1 and obs[13:26].sum() == 1          # y = 6
    assert obs[26] == 1 and obs[26:30].sum() == 1              # facing right
    assert obs[30] == 1 and obs[30:33].sum() == 1              # carrying nothing
    assert not obs[33:].any()                                  # both doors shut
    for a in bfs.plan(env, "yellow_door"):
        obs, *_ = env.step(a)
    assert obs[31] == 1 and obs[30] == 0                       # carrying the yellow key (slot 1)
    assert obs[33] == 1 and obs[34] == 0                       # yellow door open, blue shut
    assert make("fourroom").observation_space.shape == (13 + 13 + 4 + 1,)


def test_image_observation_is_minigrid_full_grid_encoding():
    env = make("keydoor", obs_mode="image")
    u = env.unwrapped
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for t in range(200):
        full = u.grid.encode()
        x, y = u.agent_pos
        full[x, y] = (OBJECT_TO_IDX["agent"], COLOR_TO_IDX["red"], u.agent_dir)
        np.testing.assert_array_equal(obs, full.reshape(-1).astype(np.float32))
        plan = bfs.plan(env) if t == 100 else None
        obs, *_ = env.step(plan[0] if plan else int(rng.integers(5)))
    assert env.observation_space.shape == (13 * 13 * 3,)


def test_action_subset_and_bad_action():
    env = make("keydoor", seed=0)
    assert env.action_space == gym.spaces.Discrete(5)
    assert env.unwrapped.action_names == ["left", "right", "forward", "pickup", "toggle"]
    env.step(4)  # index 4 is MiniGrid's toggle (5), not drop (4): must not raise or drop anything
    with pytest.raises(ValueError, match=r"outside Discrete\(5\); actions are \['left'"):
        env.step(5)


def test_rewards_and_truncation():
    env = make("keydoor", seed=0, max_steps=30)
    total = 0.0
    for a in bfs.plan(env):
        _, r, te, tr, info = env.step(a)
        total += r
    assert te and not tr and info["is_success"] and total == pytest.approx(1 - 0.9 * 19 / 30)
    env = make("keydoor", seed=0, max_steps=10)
    rewards, truncs = [], []
    for _ in range(10):
        _, r, te, tr, info = env.step(0)
        rewards.append(r)
        truncs.append(tr)
    assert rewards == [0.0] * 10 and truncs == [False] * 9 + [True] and not info["is_success"]


def test_bad_constructor_arguments():
    cat = get_task("keydoor").catalogue_path
    with pytest.raises(SpecError, match="obs_mode='rgb'.*use 'symbolic', 'image' or 'egocentric'"):
        MazeEnv(catalogue=cat, obs_mode="rgb")
    with pytest.raises(SpecError, match="max_steps=0 must be a positive int"):
        MazeEnv(catalogue=cat, max_steps=0)
    with pytest.raises(SpecError, match="start='anywhere' is not supported; use 'cell' or 'room'"):
        MazeEnv(catalogue=cat, start="anywhere")


def _walk_from(lay, cell, seen):
    # every free cell 4-connected to `cell`, found by flood fill over the ASCII rows themselves
    x, y = cell
    if (x, y) in seen or lay.rows[y][x] not in ".A":
        return
    seen.add((x, y))
    for nxt in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
        _walk_from(lay, nxt, seen)


def _start_cell(env, seed):
    env.reset(seed=seed)
    return tuple(env.unwrapped.agent_pos)


@pytest.mark.parametrize("task", ["keydoor", "vault", "threepair"])
def test_a_room_start_draws_every_free_cell_of_the_start_room_and_only_those(task):
    lay = make(task).unwrapped.spec_maze.layout
    room: set = set()
    _walk_from(lay, lay.agent_start, room)
    assert set(lay.start_room()) == room and lay.start_room()[0] == lay.agent_start
    # the room ends at the first wall with a door: vault's start room is x 1-5 less its two keys
    if task == "vault":
        assert room == {(x, y) for x in range(1, 6) for y in range(1, 12)} - {(2, 3), (2, 9)}
    env = make(task, start="room")
    drawn = [_start_cell(env, s) for s in range(300)]
    assert set(drawn) <= room and len(set(drawn)) > len(room) // 2
    again = make(task, start="room")
    assert drawn[:20] == [_start_cell(again, s) for s in range(20)]
    # the default starts on A in every episode
    fixed = make(task)
    assert {_start_cell(fixed, s) for s in range(20)} == {lay.agent_start}


@pytest.mark.parametrize("task", MINIGRID_TASKS)
def test_each_subgoal_becomes_true_after_its_plan_and_not_before(task):
    for i, name in enumerate(make(task).unwrapped.subgoal_names):
        env = make(task, seed=i)
        u = env.unwrapped
        assert not u.subgoal_achieved()[i], f"{name} holds at the start"
        actions = bfs.plan(env, name)
        assert actions, name
        for k, a in enumerate(actions):
            _, _, te, _, info = env.step(a)
            assert np.array_equal(info["subgoals"], u.subgoal_achieved())
            assert info["subgoals"][i] == (k == len(actions) - 1), (name, k)
        assert info["is_success"] == (name == "goal") == te


def test_subgoal_targets():
    env = make("keydoor_incorrect", seed=0)
    u = env.unwrapped
    targets = [u.subgoal_target(i) for i in range(len(u.subgoal_names))]
    assert targets == [(4, 3), (8, 4), (4, 9), (8, 8), (11, 6), (1, 1), (1, 11), (11, 1), (11, 11)]
    for a in bfs.plan(env, "yellow_key"):
        env.step(a)
    assert u.subgoal_target(0) == tuple(int(v) for v in u.agent_pos)  # carried: already there
    with pytest.raises(IndexError, match="this task has 9"):
        u.subgoal_target(9)
    fr = make("fourroom", seed=0).unwrapped
    assert [fr.subgoal_target(i) for i in range(5)] == [(6, 3), (3, 6), (9, 6), (6, 9), (11, 11)]


def test_dropped_key_moves_its_target(tmp_path):
    (tmp_path / "d.txt").write_text("######\n#A.yG#\n#....#\n######\n")
    (tmp_path / "d.yaml").write_text(textwrap.dedent("""\
        task: d
        family: minigrid
        options:
          layout: d.txt
          legend: {y: {type: key, color: yellow}}
          actions: [left, right, forward, pickup, drop]
        subgoals:
          - {name: key, kind: carrying, args: {color: yellow}}
          - {name: goal, kind: goal}
        """))
    env = make(tmp_path / "d.yaml", seed=0)
    u = env.unwrapped
    assert u.subgoal_target(0) == (3, 1)
    for a in (2, 3, 1, 4):  # forward to (2,1), pickup, turn to face down, drop at (2,2)
        _, _, _, _, info = env.step(a)
    assert not info["subgoals"][0] and u.subgoal_target(0) == (2, 2)


def test_info_contract_after_reset_and_step():
    env = make("fourroom")
    obs, info = env.reset(seed=0)
    assert info["subgoals"].dtype == np.bool_ and info["subgoals"].shape == (5,)
    assert info["is_success"] is False
    _, _, _, _, info = env.step(2)
    assert set(info) == {"subgoals", "is_success"}


def test_rgb_render():
    env = make("keydoor", render_mode="rgb_array", tile_size=8)
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (13 * 8, 13 * 8, 3) and frame.dtype == np.uint8 and frame.std() > 0


@pytest.mark.parametrize("task", ["keydoor", "fourroom"])
def test_subgoal_potential_is_minus_manhattan_distance_to_each_target(task):
    import torch

    register()
    env = make(task)
    u = env.unwrapped
    phi = u.subgoal_potential()
    scale = u.grid.width + u.grid.height
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=1)
    for _ in range(200):
        x, y = u.agent_pos
        want = [-(abs(x - u.subgoal_target(i)[0]) + abs(y - u.subgoal_target(i)[1])) / scale
                for i in range(len(u.subgoal_names)) if u.carrying is None]
        got = phi(torch.as_tensor(obs)[None])[0]
        if want:
            assert got.tolist() == pytest.approx(want)
        obs, _, term, trunc, _ = env.step(int(rng.integers(env.action_space.n)))
        if term or trunc:
            obs, _ = env.reset(seed=2)
