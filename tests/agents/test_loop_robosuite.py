"""The one HRL loop on the robosuite arm tasks: short training smoke runs through ``experiments.run.train``.

Scripted low level (the fast CPU option), tiny budgets and short horizons: each run must write the same
run directory as the MiniGrid tasks, log one metrics row per episode, and (HUBS-GO) move the critic.
One h-DQN run checks the critic-free agent on the same loop; one learned-low-level run checks that
GoalTD3 trains inside the loop and resumes from its checkpoint.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

pytest.importorskip("robosuite", reason="robosuite is not installed: the arm-task tests are skipped (install "
                    "the 'robosuite' extra; 'make test' sets HUBSGO_REQUIRE_ROBOSUITE=1 and fails instead)")

from hubsgo_ppl.experiments.logger import read_csv_rows  # noqa: E402
from hubsgo_ppl.experiments.run import RunConfig, evaluate, load_run, train  # noqa: E402

pytestmark = pytest.mark.mujoco

# tiny budgets: a few episodes of 100 steps; batch 8 so the high level and the critic update early
SMOKE = ["env.horizon=100", "loop.option_steps=25", "high.batch_size=8", "high.learning_starts=8"]


@pytest.mark.parametrize("task", ["stack_cubes", "push_any_one", "collect_three_balls"])
def test_hubsgo_scripted_smoke_run(task, tmp_path):
    out = tmp_path / task
    summary = train(RunConfig(task=task, steps=400, seed=0, overrides=SMOKE), out, progress=False)
    assert summary["finished"] and summary["env_steps"] >= 400 and summary["episodes"] >= 4
    for name in ("config.yaml", "metrics.csv", "critic_history.csv", "checkpoint.pt", "subgoals.json",
                 "learning_curve.png"):
        assert (out / name).is_file(), name
    rows = read_csv_rows(out / "metrics.csv")
    assert [int(r["episode"]) for r in rows] == list(range(summary["episodes"]))
    assert sum(int(r["length"]) for r in rows) == summary["env_steps"]
    # an episode ends at the horizon (100) or on success; an option at 25 steps or its sub-goal
    assert all(int(r["length"]) == 100 or int(r["success"]) for r in rows)
    assert all(int(r["options"]) >= -(-int(r["length"]) // 25) for r in rows)
    # the default (outcome) likelihood's evidence is the successful episodes: the critic updates from
    # the first success on, and not before
    updated = [r.get("critic/loss") not in (None, "") for r in rows]
    first = next((i for i, r in enumerate(rows) if int(r["success"])), None)
    assert updated == [first is not None and i > first for i in range(len(rows))] or (
        first is not None and not any(updated[: first + 1]))

    _, env, agent, _ = load_run(out)
    names = list(env.unwrapped.subgoal_names)
    critic = agent.filter.critic
    start = critic.prior.natural_params()[0]
    moved = float((critic._theta.detach() - start).abs().max())
    assert (moved > 1e-4) == any(updated)      # TraceGraph_ELBO steps moved q away from the prior, or none ran
    table = json.loads((out / "subgoals.json").read_text())
    assert table["names"] == names and set(table["marginals"]) == set(names)
    assert table["ranking"] and all(set(r["subgoals"]) <= set(names) for r in table["ranking"])
    env.close()


def test_hdqn_scripted_smoke_run_and_greedy_evaluation(tmp_path, record_episodes):
    out = tmp_path / "hdqn"
    train(RunConfig(task="push_any_one", agent="hdqn", steps=300, seed=1, overrides=SMOKE), out, progress=False)
    assert (out / "checkpoint.pt").is_file() and not (out / "subgoals.json").exists()
    rows = read_csv_rows(out / "metrics.csv")
    assert len(rows) == 3 and rows[-1].get("high/td_loss") not in (None, "")
    result = evaluate(out, episodes=2)
    played = record_episodes                      # the eval env's own step results
    assert result["episodes"] == len(played) == 2
    assert result["success_rate"] == np.mean([e["success"] for e in played])
    assert result["returns"] == [e["return"] for e in played]
    for e in played:      # sparse reward: 1 on the success step, which ends the episode; else the horizon
        assert e["return"] == float(e["success"]) and e["terminated"] == e["success"]
        assert e["success"] or (e["truncated"] and e["length"] == e["max_steps"] == 100)
    assert (out / "eval.json").is_file()


def test_learned_low_level_trains_in_the_loop_and_resumes(tmp_path):
    out = tmp_path / "learned"
    low = ["low.hidden=[32, 32]", "low.skill=null", "low.batch_size=32", "low.learning_starts=32"]
    cfg = RunConfig(task="stack_cubes", steps=200, seed=2, low_level="learned", checkpoint_steps=1,
                    overrides=SMOKE + low)
    train(cfg, out, progress=False, max_episodes=1)
    _, env, agent, _ = load_run(out)
    assert type(agent.low).__name__ == "GoalTD3"
    assert len(agent.low.buffer) > 100           # one episode, relabelled copies included
    assert agent.low.updates > 0
    actor = {k: v.clone() for k, v in agent.low.actor.state_dict().items()}
    env.close()
    summary = train(cfg, out, resume=True, progress=False)
    assert summary["finished"] and summary["episodes"] == 2
    rows = read_csv_rows(out / "metrics.csv")
    assert [int(r["episode"]) for r in rows] == [0, 1]
    assert np.isfinite(float(rows[-1]["low/critic_loss"]))
    _, env, agent, _ = load_run(out)
    assert any(not torch.equal(actor[k], v) for k, v in agent.low.actor.state_dict().items())
    env.close()
