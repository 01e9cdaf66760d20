"""HIGL: HIRO bit for bit without its landmark term, the landmark graph on a trained-for-a-while agent,
checkpoint round trip through the safe loader, seeded determinism and a run through `hubsgo train`."""

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.higl import HIGL, build_higl
from hubsgo_ppl.agents.hiro import build_hiro
from hubsgo_ppl.agents.presets import preset
from hubsgo_ppl.envs import make, register
from hubsgo_ppl.experiments.io import load_checkpoint, save_torch
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, train

SMALL = dict(hidden=[16], batch_size=8, low_learning_starts=200, high_learning_starts=8)


def _cfg(steps=10_000, **higl):
    cfg = preset("minigrid")
    cfg["steps"] = steps
    cfg["hiro"].update(SMALL)
    cfg["higl"].update(SMALL, graph_every=3, landmarks_coverage=6, landmarks_novelty=3, landmark_pool=50, **higl)
    return cfg


def _weights(agent):
    return [p.detach().clone() for p in agent.high.actor.parameters()]


def test_without_the_landmark_term_higl_is_hiro_bit_for_bit():
    register()
    hiro = build_hiro(make("fourroom_cardinal", max_steps=120), _cfg(), seed=2)
    higl = build_higl(make("fourroom_cardinal", max_steps=120), _cfg(landmark_weight=0.0), seed=2)
    for _ in range(2):
        assert hiro.train_chunk() == higl.train_chunk()
    assert all(torch.equal(a, b) for a, b in zip(_weights(hiro), _weights(higl)))
    assert higl.graph is None and len(higl.novelty) > 1


def test_landmarks_guide_the_high_level_and_the_graph_is_consistent():
    register()
    higl = build_higl(make("fourroom_cardinal", max_steps=120), _cfg(), seed=0)
    hiro = build_hiro(make("fourroom_cardinal", max_steps=120), _cfg(), seed=0)
    stats = higl.train_chunk()[0]
    hiro.train_chunk()
    assert higl.actor_updates > 0 and higl.graph is not None
    assert not all(torch.equal(a, b) for a, b in zip(_weights(hiro), _weights(higl)))
    nodes, to_target = higl.graph["nodes"], higl.graph["to_target"]
    assert len(nodes) == len(to_target) + 1 <= 6 + 3 + 1
    # coverage landmarks are distinct cells; every node is a cell of the grid
    assert np.all(nodes == np.round(nodes)) and len({tuple(n) for n in nodes[:-1]}) >= 2
    # the target: the goal cell once a reward was met, else the least-visited cell's
    if higl.target is not None:
        assert tuple(higl.target) == (11.0, 11.0)
    else:
        assert higl.best_reward == 0.0
    obs = torch.as_tensor(higl.low_buf.data["obs"][:5])
    chosen = higl.select(obs, torch.as_tensor(higl.goals.achieved(obs.numpy())))
    assert all(any(np.array_equal(c, n) for n in nodes) for c in chosen)
    assert np.isfinite(stats.scalars["high/landmark_loss"])


def test_checkpoint_round_trip_through_the_safe_loader_continues_identically(tmp_path):
    register()
    a = build_higl(make("keydoor_cardinal", max_steps=120), _cfg(), seed=4)
    a.train_chunk()
    assert a.graph is not None
    save_torch(tmp_path / "ckpt.pt", {"format": 1, "agent": a.state_dict()})
    next_a = a.train_chunk()[0]
    b = build_higl(make("keydoor_cardinal", max_steps=120), _cfg(), seed=4)
    b.load_state_dict(load_checkpoint(tmp_path / "ckpt.pt")["agent"])
    next_b = b.train_chunk()[0]
    assert next_a == next_b and next_a.episode == 1
    assert all(torch.equal(x, y) for x, y in zip(_weights(a), _weights(b)))


def test_seeded_runs_reproduce_and_seeds_differ():
    register()
    runs = [build_higl(make("fourroom_cardinal", max_steps=120), _cfg(), seed=s) for s in (1, 1, 2)]
    first = [r.train_chunk()[0] for r in runs]
    assert first[0] == first[1] and first[0] != first[2]


def test_higl_trains_through_the_cli_run_and_rejects_bad_settings(tmp_path):
    overrides = [f"higl.{k}={v}" for k, v in SMALL.items()] + ["higl.graph_every=2", "env.max_steps=300"]
    summary = train(RunConfig(task="keydoor_cardinal", agent="higl", steps=1, seed=0, overrides=overrides),
                    tmp_path / "run", progress=False)
    rows = read_csv_rows(tmp_path / "run" / "metrics.csv")
    assert summary["finished"] and len(rows) == 1 and float(rows[0]["high/landmark_loss"]) >= 0
    cfg = _cfg()
    cfg["higl"]["landmark_step"] = 0
    with pytest.raises(ValueError, match=r"^higl.landmark_step takes a number in \(0, 1\] \(default 1.0\), got 0$"):
        build_higl(make("keydoor_cardinal", max_steps=120), cfg, seed=0)
    assert isinstance(build_higl(make("keydoor_cardinal", max_steps=120), _cfg(), seed=0), HIGL)


@pytest.mark.mujoco
def test_higl_trains_on_an_arm_task(tmp_path):
    """The TD3 low level's value gives the distances; visit counts over 5 cm cells of the end-effector."""
    overrides = [f"higl.{k}={v}" for k, v in SMALL.items()] + ["higl.low_learning_starts=100", "higl.graph_every=2"]
    summary = train(RunConfig(task="push_any_one", agent="higl", steps=1, seed=0, overrides=overrides),
                    tmp_path / "arm", progress=False)
    rows = read_csv_rows(tmp_path / "arm" / "metrics.csv")
    assert summary["finished"] and np.isfinite(float(rows[0]["high/landmark_loss"]))
    assert np.isfinite(float(rows[0]["low/critic_loss"]))
