"""``obs_mode: image``: the shaping potential read from MiniGrid's full-grid encoding, and runs that
train with it by default."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import yaml
from minigrid.core.constants import OBJECT_TO_IDX

from hubsgo_ppl.cli import main
from hubsgo_ppl.envs import make


def _same_potentials(task, reference, steps=150, seeds=4):
    """The largest difference between the image potential and ``reference``'s on the states a random
    rollout visits (both envs see the same seeds and actions), and how many states had a carried object."""
    envs = [make(task, obs_mode=reference), make(task, obs_mode="image")]
    phis = [e.unwrapped.subgoal_potential() for e in envs]
    rng = np.random.default_rng(0)
    worst, compared = 0.0, 0
    for seed in range(seeds):
        obs = [e.reset(seed=seed)[0] for e in envs]
        for _ in range(steps):
            ref, img = (phi(torch.as_tensor(o)[None])[0] for phi, o in zip(phis, obs))
            worst, compared = max(worst, float((ref - img).abs().max())), compared + 1
            action = int(rng.integers(envs[0].action_space.n))
            out = [e.step(action) for e in envs]
            obs = [o[0] for o in out]
            if out[0][2] or out[0][3]:
                break
    for e in envs:
        e.close()
    return worst, compared


@pytest.mark.parametrize("task", ["keydoor", "fourroom"])
def test_a_maze_image_potential_is_its_symbolic_one(task):
    worst, compared = _same_potentials(task, "symbolic")
    assert compared > 100 and worst < 1e-6


@pytest.mark.parametrize("task", ["doorkey_8x8", "unlockpickup"])
def test_a_registered_image_potential_is_its_egocentric_one(task):
    worst, compared = _same_potentials(task, "egocentric")
    assert compared > 100 and worst < 1e-6


def test_a_registered_goal_without_a_goal_square_is_the_missions_object(tmp_path):
    path = tmp_path / "unlock.yaml"
    path.write_text(yaml.safe_dump({
        "task": "unlock", "family": "minigrid", "options": {"gym_id": "MiniGrid-Unlock-v0"},
        "subgoals": [{"name": "key", "kind": "carrying", "args": {"type": "key"}},
                     {"name": "door", "kind": "door_open", "args": {"locked": True}},
                     {"name": "goal", "kind": "goal"}]}))
    worst, compared = _same_potentials(str(path), "egocentric")
    assert compared > 100 and worst < 1e-6


def test_the_image_potential_reads_the_agents_cell_from_the_image():
    env = make("keydoor", obs_mode="image")
    obs, _ = env.reset(seed=0)
    u = env.unwrapped
    phi = u.subgoal_potential()
    x, y = u.agent_pos
    W, H = u.grid.width, u.grid.height
    targets = [u.subgoal_target(i) for i in range(len(u.subgoal_names))]
    want = [-(abs(x - tx) + abs(y - ty)) / (W + H) for tx, ty in targets]
    assert phi(torch.as_tensor(obs)[None])[0].tolist() == pytest.approx(want)
    img = obs.reshape(W, H, 3).copy()           # the same image with the agent on another empty cell
    nx, ny = max(zip(*np.nonzero(img[..., 0] == OBJECT_TO_IDX["empty"])), key=lambda c: abs(c[0] - x) + abs(c[1] - y))
    img[nx, ny], img[x, y] = img[x, y], (OBJECT_TO_IDX["empty"], 0, 0)
    moved = [-(abs(nx - tx) + abs(ny - ty)) / (W + H) for tx, ty in targets]
    assert (nx, ny) != (x, y) and phi(torch.as_tensor(img.reshape(-1))[None])[0].tolist() == pytest.approx(moved)


@pytest.mark.parametrize("argv", [
    ["keydoor", "--set", "env.obs_mode=image", "--steps", "300"],
    ["doorkey_8x8", "--set", "env.obs_mode=image", "--set", "env.max_steps=60", "--steps", "300"],
])
def test_image_observations_train_with_the_default_shaping(argv, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", *argv, "--out", str(run), "--no-progress"]) == 0, capsys.readouterr().err
    assert (run / "checkpoint.pt").is_file()
    hyper = yaml.safe_load((run / "config.yaml").read_text())["hyper"]
    assert hyper["env"]["obs_mode"] == "image" and hyper["low"]["shaping"] > 0
