"""The training driver calls its callbacks in order, and a user's callback can stop a run."""

import pytest

from hubsgo_ppl.experiments import Callback, RunConfig, RunError, train
from hubsgo_ppl.experiments.io import load_checkpoint
from hubsgo_ppl.experiments.logger import read_csv_rows

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def _cfg(steps=900):
    return RunConfig(task="keydoor", steps=steps, seed=3, checkpoint_steps=300, overrides=TINY)


class Recorder(Callback):
    def __init__(self):
        self.calls = []

    def on_training_start(self, run):
        self.calls.append(("start", run.agent.env_steps))

    def on_chunk_start(self, run):
        self.calls.append(("chunk_start", run.agent.env_steps))

    def on_episode(self, run, stats):
        self.calls.append(("episode", stats.episode))

    def on_chunk_end(self, run):
        ckpt = run.out / "checkpoint.pt"
        self.calls.append(("chunk_end", run.agent.env_steps,
                           load_checkpoint(ckpt)["env_steps"] if ckpt.exists() else None))

    def on_training_end(self, run):
        self.calls.append(("end", run.agent.env_steps, (run.out / "subgoals.json").exists()))

    def on_close(self, run):
        self.calls.append(("close",))


def test_callbacks_are_called_in_order_after_the_harness_own(tmp_path):
    rec = Recorder()
    out = tmp_path / "run"
    summary = train(_cfg(), out, progress=False, callbacks=[rec])
    kinds = [c[0] for c in rec.calls]
    assert kinds[0] == "start" and kinds[-2:] == ["end", "close"]
    episodes = [c[1] for c in rec.calls if c[0] == "episode"]
    rows = read_csv_rows(out / "metrics.csv")
    assert episodes == [int(r["episode"]) for r in rows] == list(range(summary["episodes"]))
    # each chunk: start, its episodes (one for the HRL loop), end
    body = kinds[1:-2]
    assert body == ["chunk_start", "episode", "chunk_end"] * len(episodes)
    every = 300
    for start, end in zip([c for c in rec.calls if c[0] == "chunk_start"], [c for c in rec.calls if c[0] == "chunk_end"]):
        if end[1] // every > start[1] // every:      # a chunk that crossed a multiple: checkpointed before us
            assert end[2] == end[1]
    assert rec.calls[-2] == ("end", summary["env_steps"], True), "G* is written before a user's on_training_end"


class StopAfter(Callback):
    def __init__(self, episodes):
        self.episodes = episodes

    def on_episode(self, run, stats):
        return stats.episode + 1 < self.episodes


def test_a_user_callback_stops_the_run_as_a_pause_that_resume_continues(tmp_path):
    out = tmp_path / "run"
    summary = train(_cfg(), out, progress=False, callbacks=[StopAfter(2)])
    assert not summary["finished"] and summary["episodes"] == 2
    assert len(read_csv_rows(out / "metrics.csv")) == 2
    held = load_checkpoint(out / "checkpoint.pt")
    assert held["episodes"] == 2 and held["env_steps"] == summary["env_steps"]
    assert not (out / "subgoals.json").exists()
    resumed = train(_cfg(), out, resume=True, progress=False)
    assert resumed["finished"] and (out / "subgoals.json").exists()


def test_callbacks_must_be_callback_objects(tmp_path):
    with pytest.raises(RunError, match="callbacks must be Callback objects"):
        train(_cfg(), tmp_path / "run", progress=False, callbacks=[lambda run: None])
    assert not (tmp_path / "run").exists()


def test_critic_history_ends_with_the_marginals_g_star_is_read_from(tmp_path):
    import json

    out = tmp_path / "run"
    summary = train(_cfg(600), out, progress=False)
    rows = read_csv_rows(out / "critic_history.csv")
    assert {r["critic"] for r in rows[:-1]} == {"training"}
    last = rows[-1]
    assert last["critic"] == ("settled" if "settled" in summary else "final")
    assert int(last["episode"]) == summary["episodes"] and int(last["env_steps"]) == summary["env_steps"]
    g_star = json.loads((out / "subgoals.json").read_text())["marginals"]
    assert {n: float(last[n]) for n in g_star} == pytest.approx(g_star, abs=1e-5)
