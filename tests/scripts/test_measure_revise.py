"""scripts/measure_revise.py: the per-run measures, on a known metrics.csv."""

from __future__ import annotations

import csv
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
import measure_revise  # noqa: E402  (a script module, not a package)


def _write(run: Path, lengths: list[int], success: list[int]) -> None:
    run.mkdir()
    steps = 0
    with open(run / "metrics.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["episode", "env_steps", "length", "success", "return"])
        for i, (n, ok) in enumerate(zip(lengths, success)):
            steps += n
            w.writerow([i, steps, n, ok, 0.9 if ok else 0.0])


def test_failures_and_settled_length_count_episodes_that_began_after_the_pause(tmp_path):
    # 10 episodes of 100 steps (ending at 100..1000), then 70 of 10 steps; the pause at 1,000 steps:
    # the episodes after it are the 70 short ones, two of which fail
    lengths = [100] * 10 + [10] * 70
    success = [0] * 10 + [1] * 70
    success[10 + 3] = success[10 + 40] = 0
    _write(tmp_path / "run", lengths, success)
    out = measure_revise.run_stats(tmp_path / "run", budget=1_700, pause=1_000)
    assert out["failures_after_pause"] == 2
    assert out["settled_length"] == 10
    assert out["first_success"] == 1_010          # the first 10-step episode, after 1,000 steps of failures
    assert out["episodes"] == 80
    assert out["final_success"] == 1.0
    # the last third of the budget: the episodes ending after 1,133 steps (one failure among them)
    tail = [s for s, e in zip(success, [sum(lengths[:i + 1]) for i in range(80)]) if e > 1_700 * 2 / 3]
    assert out["late_return"] == pytest.approx(0.9 * sum(tail) / len(tail))


def test_without_a_pause_the_after_pause_measures_are_undefined(tmp_path):
    _write(tmp_path / "run", [50] * 30, [1] * 30)
    out = measure_revise.run_stats(tmp_path / "run", budget=1_500)
    assert math.isnan(out["failures_after_pause"]) and math.isnan(out["settled_length"])
    assert out["steps_to_90"] == 20 * 50
    assert out["first_success"] == 50


def test_the_corrected_spec_drops_suggested_sub_goals_and_with_keep_linked_only_unrelated_ones(tmp_path):
    import yaml

    spec = {"name": "toy", "task": "keydoor_incorrect", "subgoals": ["a_key", "a_door", "b_key", "b_door", "goal", "corner"],
            "edges": [["a_key", "a_door", "positive"], ["b_key", "b_door", "positive"], ["a_door", "goal", "positive"],
                      ["b_door", "goal", "positive"], ["a_key", "b_key", "negative"]]}
    review = {"suggested_drops": [{"name": "b_key", "success_frequency": 0.0},
                                  {"name": "b_door", "success_frequency": 0.0},
                                  {"name": "corner", "success_frequency": 0.25},
                                  {"name": "goal", "success_frequency": 1.0}],      # achieved: kept
              "flagged_edges": [{"u": "a_key", "v": "b_key", "learned": "positive"}]}
    every = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "all.yaml").read_text())
    assert every["subgoals"] == ["a_key", "a_door", "goal"]
    assert every["edges"] == [["a_key", "a_door", "positive"], ["a_door", "goal", "positive"]]
    linked = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "linked.yaml",
                                                          keep_linked=True).read_text())
    assert linked["subgoals"] == ["a_key", "a_door", "b_key", "b_door", "goal"]
    # the flagged edge takes its learned sign; the others keep the human's
    assert ["a_key", "b_key", "positive"] in linked["edges"] and len(linked["edges"]) == 5


def test_unlink_held_removes_only_the_positive_edges_the_review_names(tmp_path):
    import yaml

    spec = {"name": "toy", "task": "detour", "subgoals": ["r_key", "r_door", "goal", "corner"],
            "edges": [["r_key", "r_door", "positive"], ["r_door", "goal", "positive"], ["corner", "goal", "positive"]]}
    review = {"suggested_drops": [], "flagged_edges": [],
              "held_by_edges": [{"name": "corner", "success_frequency": 0.3, "positive_edges": ["goal"]}]}
    kept = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "kept.yaml").read_text())
    assert kept["edges"] == spec["edges"]                              # without the option: as before
    new = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "new.yaml", unlink_held=True).read_text())
    assert new["subgoals"] == spec["subgoals"]                          # the sub-goal stays a candidate
    assert new["edges"] == [["r_key", "r_door", "positive"], ["r_door", "goal", "positive"]]


def test_drop_held_drops_the_sub_goals_the_review_says_edges_hold_with_their_edges(tmp_path):
    import yaml

    spec = {"name": "toy", "task": "keydoor_incorrect", "subgoals": ["r_key", "r_door", "goal", "corner", "far"],
            "edges": [["r_key", "r_door", "positive"], ["r_door", "goal", "positive"], ["corner", "goal", "positive"],
                      ["far", "goal", "positive"]]}
    spec["subgoals"].append("up")
    spec["edges"].append(["up", "goal", "positive"])
    review = {"suggested_drops": [{"name": "far", "success_frequency": 0.1}], "flagged_edges": [],
              "held_by_edges": [{"name": "corner", "success_frequency": 0.3, "positive_edges": ["goal"]}],
              "held_up_by_edges": [{"name": "up", "marginal": 0.4, "success_frequency": 0.0, "positive_edges": ["goal"]}]}
    kept = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "kept.yaml").read_text())
    assert kept["subgoals"] == ["r_key", "r_door", "goal", "corner", "up"]   # without the option: the suggested drop
    new = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "new.yaml", drop_held=True).read_text())
    assert new["subgoals"] == ["r_key", "r_door", "goal"]       # held in G* and held up outside it, with their edges
    assert new["edges"] == [["r_key", "r_door", "positive"], ["r_door", "goal", "positive"]]


def test_unlink_together_removes_only_the_negative_edges_the_successes_contradict(tmp_path):
    import yaml

    spec = {"name": "toy", "task": "chain", "subgoals": ["r_key", "r_door", "b_key", "b_door", "goal"],
            "edges": [["r_key", "r_door", "positive"], ["b_key", "b_door", "positive"], ["r_key", "b_key", "negative"],
                      ["r_door", "b_door", "negative"], ["b_door", "goal", "positive"]]}
    review = {"suggested_drops": [], "flagged_edges": [],
              "negative_edges_achieved_together": [{"u": "r_key", "v": "b_key", "both_frequency": 0.9}]}
    kept = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "kept.yaml").read_text())
    assert kept["edges"] == spec["edges"]                              # without the option: as before
    new = yaml.safe_load(measure_revise.corrected_spec(review, spec, tmp_path / "new.yaml",
                                                       unlink_together=True).read_text())
    assert new["subgoals"] == spec["subgoals"]
    assert new["edges"] == [e for e in spec["edges"] if e[:2] != ["r_key", "b_key"]]


def test_g_star_reads_whether_the_top_set_is_one_route(tmp_path):
    import json

    for name, top in (("route", ["purple_key", "purple_door", "goal"]),
                      ("extra", ["purple_key", "purple_door", "goal", "far_corner"])):
        (tmp_path / name).mkdir()
        (tmp_path / name / "subgoals.json").write_text(json.dumps({"ranking": [{"subgoals": top, "prob": 0.5}]}))
    assert measure_revise.g_star(tmp_path / "route", "detour") == {"g_star_one_route": 1.0, "g_star_p": 0.5}
    assert measure_revise.g_star(tmp_path / "extra", "detour")["g_star_one_route"] == 0.0
    assert math.isnan(measure_revise.g_star(tmp_path / "route", "unknown_maze")["g_star_one_route"])


def test_suggested_revises_with_the_reviews_own_suggested_spec_end_to_end(tmp_path, capsys):
    """``--suggested``: the human passes the review's suggested_spec.yaml to ``hubsgo revise`` as written;
    the three arms run, and the protocol's own corrections cannot be combined with it."""
    import json

    import yaml

    out = tmp_path / "out"
    assert measure_revise.main(["--out", str(out), "--smoke", "--suggested"]) == 0
    base = out / "keydoor_incorrect" / "seed0"
    review_dir = base / "revised" / "review"
    assert yaml.safe_load((base / "corrected.yaml").read_text()) == yaml.safe_load((review_dir / "suggested_spec.yaml").read_text())
    assert json.loads((out / "settings.json").read_text())["suggested"] is True
    with (out / "results.csv").open(newline="") as f:
        assert [r["arm"] for r in csv.DictReader(f)] == list(measure_revise.ARMS)
    assert (base / "revised" / "revisions" / "001" / "spec_after.yaml").is_file()
    with pytest.raises(SystemExit):
        measure_revise.main(["--out", str(tmp_path / "other"), "--smoke", "--suggested", "--drop-held"])
    assert "do not apply to it" in capsys.readouterr().err
