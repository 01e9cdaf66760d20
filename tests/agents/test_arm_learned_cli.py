"""The arm tasks with the learned low level, through the CLI a user runs: a tiny-budget ``train`` paused
and resumed, then ``evaluate``, ``review`` and ``revise`` on the run; and the same seed giving the same
``metrics.csv``. Budgets are a few short episodes: robosuite steps at about 150/s on one core."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import yaml

pytest.importorskip("robosuite", reason="robosuite is not installed: the arm-task tests are skipped (install "
                    "the 'robosuite' extra; 'make test' sets HUBSGO_REQUIRE_ROBOSUITE=1 and fails instead)")

from hubsgo_ppl.cli import main  # noqa: E402

pytestmark = pytest.mark.mujoco

# 60-step episodes of 20-step options; the low level (from the shipped reach skill) trains from its 32nd
# stored transition on
TINY = ["--set", "env.horizon=60", "--set", "loop.option_steps=20", "--set", "high.learning_starts=4",
        "--set", "high.batch_size=4", "--set", "low.learning_starts=32", "--set", "low.batch_size=32",
        "--set", "high.hidden=[32]"]


def _metrics(run) -> list[dict[str, str]]:
    with (run / "metrics.csv").open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("task", ["push_any_one", "stack_cubes", "collect_three_balls"])
def test_a_learned_low_level_run_pauses_resumes_and_is_read_by_every_command(task, tmp_path):
    run = tmp_path / task
    base = ["train", task, "--low-level", "learned", "--steps", "120", "--seed", "0", "--out", str(run),
            "--no-progress", *TINY]
    assert main([*base, "--stop-at", "60"]) == 0
    assert len(_metrics(run)) == 1
    assert main([*base, "--resume"]) == 0
    rows = _metrics(run)
    assert [int(r["episode"]) for r in rows] == [0, 1] and int(rows[-1]["env_steps"]) == 120
    assert rows[-1]["low/critic_loss"] not in ("", None)          # the low level trained in the loop
    assert main(["evaluate", str(run), "--episodes", "1"]) == 0
    assert json.loads((run / "eval.json").read_text())["episodes"] == 1
    assert main(["review", str(run), "--no-gif"]) == 0
    assert (run / "review" / "review.json").is_file()
    assert main(["revise", str(run), "--model", f"{task}-specific", "--no-train"]) == 0
    assert (run / "revisions.csv").is_file()


def test_the_same_seed_gives_the_same_metrics_with_the_learned_low_level(tmp_path):
    def train(out):
        assert main(["train", "push_any_one", "--low-level", "learned", "--steps", "80", "--seed", "3",
                     "--out", str(out), "--no-progress", *TINY, "--set", "env.horizon=40"]) == 0
        return [{k: v for k, v in r.items() if k != "wall_time"} for r in _metrics(out)]

    first, second = train(tmp_path / "a"), train(tmp_path / "b")
    assert len(first) == 2 and first == second
    assert first[-1]["low/critic_loss"] not in ("", None)


ARMS = Path(__file__).resolve().parents[2] / "examples" / "arms"
USER_TASKS = sorted(p.stem for p in ARMS.glob("*.yaml") if not p.stem.endswith("-spec"))


@pytest.mark.parametrize("task", USER_TASKS)
def test_a_user_written_arm_task_trains_on_the_family_defaults(tmp_path, task):
    """Each catalogue in examples/arms (tasks the package does not ship: a fourth cube colour, two pads,
    three cubes, a lower wall), with its own spec and nothing else: the learned low level, the robosuite
    family's settings."""
    run = tmp_path / task
    assert main(["train", str(ARMS / f"{task}.yaml"), "--model", str(ARMS / f"{task}-spec.yaml"),
                 "--low-level", "learned", "--steps", "80", "--seed", "0", "--out", str(run), "--no-progress",
                 "--set", "env.horizon=40", "--set", "low.learning_starts=32"]) == 0
    rows = _metrics(run)
    assert len(rows) == 2 and rows[-1]["low/critic_loss"] not in ("", None)
    listed = [s["name"] for s in yaml.safe_load((ARMS / f"{task}.yaml").read_text())["subgoals"]]
    assert json.loads((run / "subgoals.json").read_text())["names"] == listed
    assert main(["evaluate", str(run), "--episodes", "1"]) == 0
