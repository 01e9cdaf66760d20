"""The mazes shipped for the critic's acceptance runs train end to end at a tiny budget, on the
MiniGrid family default and their default spec, and write a G* over their own sub-goals."""

import json

import pytest

from hubsgo_ppl.experiments.run import RunConfig, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=200"]


@pytest.mark.parametrize("task", ["threepair", "twowall", "keydoor_n17", "keydoor_n65", "vault", "detour", "annex",
                                  "gallery", "moat", "chain"])
def test_tiny_hubsgo_run_on_each_new_maze(task, tmp_path):
    from hubsgo_ppl.envs import get_task

    out = tmp_path / task
    train(RunConfig(task=task, agent="hubsgo", steps=600, seed=0, checkpoint_steps=200, overrides=TINY),
          out, progress=False)
    table = json.loads((out / "subgoals.json").read_text())
    assert table["names"] == get_task(task).catalogue.names
    assert (out / "metrics.csv").read_text().count("\n") >= 2
