"""The run harness: determinism, resume after interruption, outputs, and bad input."""

import json

import pytest

from hubsgo_ppl.experiments.io import CheckpointError
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, RunError, evaluate, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150"]


def _cfg(agent="hubsgo", steps=1500, **kw):
    return RunConfig(task="keydoor", agent=agent, steps=steps, seed=3, checkpoint_every=2,
                     overrides=TINY + ["loop.option_steps=15"], **kw)


def _rows(path):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in read_csv_rows(path / "metrics.csv")]


class Crash(Exception):
    pass


def test_same_seed_same_metrics_and_resume_after_crash_continues_identically(tmp_path):
    full = tmp_path / "full"
    train(_cfg(), full, progress=False)
    again = tmp_path / "again"
    train(_cfg(), again, progress=False)
    assert _rows(full) == _rows(again), "same seed on CPU must give identical metrics"

    crashed = tmp_path / "crashed"

    n_full = len(_rows(full))
    assert n_full >= 4, "the budget must span several episodes for this test to mean anything"

    def crash_after_checkpoint(stats):
        if stats.episode == 2:            # the checkpoint holds 2 episodes; episode 2 is logged, then lost
            raise Crash

    with pytest.raises(Crash):
        train(_cfg(), crashed, progress=False, on_episode=crash_after_checkpoint)
    assert len(_rows(crashed)) == 3
    train(_cfg(), crashed, resume=True, progress=False)
    assert _rows(crashed) == _rows(full)
    for name in ("config.yaml", "checkpoint.pt", "subgoals.json", "learning_curve.png", "critic_history.csv"):
        assert (full / name).is_file(), name
    assert list((full / "tb").glob("events.out.tfevents.*"))
    table = json.loads((full / "subgoals.json").read_text())
    assert table["num_samples"] == 10_000 and table["ranking"]
    assert abs(sum(table["marginals"].values())) > 0


@pytest.mark.parametrize("agent", ["hubsgo", "hdqn"])
def test_tiny_budget_trains_and_evaluates(tmp_path, agent):
    out = tmp_path / agent
    summary = train(_cfg(agent=agent, steps=800), out, progress=False)
    assert summary["finished"] and summary["env_steps"] >= 800
    rows = read_csv_rows(out / "metrics.csv")
    assert [int(r["episode"]) for r in rows] == list(range(len(rows)))
    result = evaluate(out, episodes=2)
    assert result["episodes"] == 2 and 0.0 <= result["success_rate"] <= 1.0
    assert 0 < result["optimal_return"] <= 1.0
    assert (out / "eval.json").is_file()


def test_bad_inputs_fail_clearly_and_lose_nothing(tmp_path):
    from hubsgo_ppl.envs import UnknownTaskError
    from hubsgo_ppl.specs import SpecError

    with pytest.raises(UnknownTaskError, match="unknown task 'nope'"):
        train(RunConfig(task="nope"), tmp_path / "x", progress=False)
    with pytest.raises(SpecError, match="use a spec written for this task"):
        train(RunConfig(task="keydoor", model="fourroom-specific"), tmp_path / "y", progress=False)
    with pytest.raises(CheckpointError, match="no checkpoint"):
        train(_cfg(), tmp_path / "empty", resume=True, progress=False)
    run = tmp_path / "run"
    train(_cfg(steps=300), run, progress=False)
    before = (run / "metrics.csv").read_bytes()
    with pytest.raises(RunError, match="already holds a run"):
        train(_cfg(steps=300), run, progress=False)
    assert (run / "metrics.csv").read_bytes() == before
    (run / "checkpoint.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(CheckpointError, match="corrupt"):
        train(_cfg(steps=600), run, resume=True, progress=False)
    assert (run / "metrics.csv").read_bytes() == before
    blocker = tmp_path / "a-file"
    blocker.write_text("x")                     # a folder cannot be made under a file, even as root
    with pytest.raises(RunError, match="cannot write there"):
        train(_cfg(steps=300), blocker / "sub", progress=False)
