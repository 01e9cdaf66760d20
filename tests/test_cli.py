"""The `hubsgo` command line: verbs work end to end; bad input gives one clear line and exit code 2."""

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml

from hubsgo_ppl.cli import main

TINY = ["--set", "high.learning_starts=8", "--set", "high.batch_size=8", "--set", "low.learning_starts=64",
        "--set", "low.batch_size=32", "--set", "low.hidden=[32]", "--set", "high.hidden=[32]",
        "--set", "loop.option_steps=15", "--set", "env.max_steps=150"]


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    return err[0]


def test_tasks_lists_every_task_with_its_catalogue(capsys):
    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    for name in ("keydoor", "fourroom", "keydoor_incorrect", "fourroom_incorrect"):
        assert f"{name}  (minigrid" in out
    assert "yellow_key" in out and "door_top" in out


def test_train_subgoals_evaluate_round_trip(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["train", "keydoor", "--steps", "600", "--seed", "1", "--out", str(run), "--no-progress",
                 *TINY]) == 0
    out = capsys.readouterr().out
    assert "G* from 10,000 critic samples" in out
    assert main(["subgoals", str(run)]) == 0
    table = capsys.readouterr().out
    assert "rank" in table and "marginals P(w=1)" in table
    assert main(["subgoals", str(run), "--samples", "50"]) == 0         # a number of samples asks for a new readout
    assert capsys.readouterr().out.startswith("G* from 50 critic samples")
    assert main(["subgoals", str(run), "--samples", "0", "--recompute"]) == 2
    assert "--samples must be a positive number" in _one_error_line(capsys)
    # a reader that goes away (`| head -1`) ends the command quietly, with no traceback
    piped = subprocess.run(f"{sys.executable} -m hubsgo_ppl.cli subgoals {run} | head -1", shell=True,
                           capture_output=True, text=True)
    assert piped.stdout.startswith("G* from 10,000") and len(piped.stdout.splitlines()) == 1
    assert piped.stderr == ""
    assert main(["evaluate", str(run), "--episodes", "2"]) == 0
    assert "greedy return" in capsys.readouterr().out
    assert json.loads((run / "eval.json").read_text())["break_cycles"] is True
    assert main(["evaluate", str(run), "--episodes", "2", "--no-break-cycles"]) == 0
    assert json.loads((run / "eval.json").read_text())["break_cycles"] is False



def test_evaluate_on_a_run_folder_it_cannot_write_still_prints_its_result(tmp_path, capsys, monkeypatch):
    import errno

    from hubsgo_ppl.experiments import run as run_module

    run = tmp_path / "run"
    assert main(["train", "keydoor", "--steps", "300", "--seed", "1", "--out", str(run), "--no-progress",
                 *TINY]) == 0
    capsys.readouterr()

    def read_only(path, obj):
        raise PermissionError(errno.EACCES, "Permission denied", str(path))

    monkeypatch.setattr(run_module, "write_json", read_only)
    assert main(["evaluate", str(run), "--episodes", "2"]) == 0
    captured = capsys.readouterr()
    assert "greedy return" in captured.out and not (run / "eval.json").exists()
    assert captured.err.strip() == (f"hubsgo: warning: {run / 'eval.json'}: not written (Permission denied); the "
                                    "result is only printed")


def test_an_empty_most_probable_set_is_explained_under_the_table():
    from hubsgo_ppl.cli.show import format_ranking

    table = {"num_samples": 10, "marginals": {"a": 0.1, "b": 0.2},
             "ranking": [{"subgoals": [], "prob": 0.7}, {"subgoals": ["a"], "prob": 0.1}]}
    text = format_ranking(table)
    assert text.splitlines()[-1].startswith("the most probable set is empty: no sub-goal's evidence outweighs")
    table["ranking"].reverse()
    assert "the most probable set is empty" not in format_ranking(table)


def test_a_critic_that_never_updated_says_its_sets_are_the_priors():
    """No success, no evidence: the table is the prior's, and the line under it says so (and not that
    the evidence failed to outweigh the prior)."""
    from hubsgo_ppl.cli.show import format_ranking
    from hubsgo_ppl.experiments.checkpoint import subgoal_table
    from hubsgo_ppl.infer.critic import SubgoalCritic
    from hubsgo_ppl.specs import load_model_spec

    critic = SubgoalCritic.from_spec(load_model_spec("keydoor-specific"), seed=0)
    table = subgoal_table(critic, list(critic.names), num_samples=200)
    assert table["updates"] == 0
    # a table written before it recorded the successes: both reasons, neither claimed
    last = format_ranking(table).splitlines()[-1]
    assert last.startswith("the critic never updated: either no training episode succeeded or the high level had not")
    table["successes"] = 0
    last = format_ranking(table).splitlines()[-1]
    assert last.startswith("the critic never updated: no training episode succeeded")
    table.update(successes=1, critic_starts={"transitions": 67, "stored": 16})
    last = format_ranking(table).splitlines()[-1]
    assert last.startswith("1 training episode succeeded, but the critic had not started updating yet (it starts "
                           "after 67 high-level transitions (options); this run stored 16); these sets are its prior's")
    assert "(your edges alone)" in last
    table["updates"] = 3
    assert "never updated" not in format_ranking(table) and "not started" not in format_ranking(table)
    # a spec without edges (graph independent): the prior alone, no edges of the user's
    spec = load_model_spec("keydoor-specific").model_copy(update={"graph": "independent", "edges": []})
    table = {**subgoal_table(SubgoalCritic.from_spec(spec, seed=0), list(critic.names), num_samples=200),
             "successes": 0}
    assert format_ranking(table).splitlines()[-1].startswith(
        "the critic never updated: no training episode succeeded, so it had no evidence, and these sets are its "
        "prior's (the spec has no edges, so the prior alone)")


def test_successes_before_the_critics_first_update_are_not_reported_as_none(tmp_path, capsys):
    """The critic waits for the high level's learning_starts: a run whose episodes succeed before then
    ends with the number of them in subgoals.json and says so under G*, in train and in subgoals."""
    import csv

    run = tmp_path / "run"
    assert main(["train", "keydoor", "--low-level", "scripted", "--steps", "150", "--set", "high.learning_starts=1000",
                 "--out", str(run), "--no-progress"]) == 0
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    won = sum(int(r["success"]) for r in rows)
    assert won >= 1, rows
    table = json.loads((run / "subgoals.json").read_text())
    assert table["updates"] == 0 and table["successes"] == won
    assert table["critic_starts"]["transitions"] == 1003 and 0 < table["critic_starts"]["stored"] < 1003
    said = f"{won} training episode{'s' * (won != 1)} succeeded, but the critic had not started updating yet"
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith(said)
    for extra in ([], ["--recompute"]):
        assert main(["subgoals", str(run), *extra]) == 0
        last = capsys.readouterr().out.strip().splitlines()[-1]
        assert last.startswith(said) and "no training episode succeeded" not in last


@pytest.mark.parametrize("argv, needle", [
    (["train", "nope"], "unknown task 'nope'"),
    (["train", "keydoor", "--model", "fourroom-specific"], "model spec 'fourroom-specific'"),
    (["train", "keydoor", "--model", "no-such-spec"], "no-such-spec"),
    (["evaluate", "/nonexistent/run"], "no such run directory"),
    (["subgoals", "/nonexistent/run"], "no such run directory"),
    (["train", "keydoor", "--model", "LATIN1_SPEC"], "not UTF-8 text (byte 9); save it as UTF-8"),
    *[([verb, "NOT_A_RUN", *extra], "not a run directory (no checkpoint.pt)")       # a folder, but not a run
      for verb, extra in (("review", []), ("render", []), ("evaluate", []), ("subgoals", []), ("diagnose", []),
                          ("revise", ["--model", "keydoor-specific"]))],
])
def test_bad_input_one_line_exit_2(argv, needle, capsys, tmp_path):
    if argv[0] == "train":
        argv = argv + ["--out", str(tmp_path / "o"), "--no-progress"]
    argv = [str(tmp_path) if a == "NOT_A_RUN" else a for a in argv]
    if "LATIN1_SPEC" in argv:
        (tmp_path / "latin.yaml").write_bytes("name: caf\u00e9\nsubgoals: [goal]\n".encode("latin-1"))
        argv = [str(tmp_path / "latin.yaml") if a == "LATIN1_SPEC" else a for a in argv]
    assert main(argv) == 2
    assert needle in _one_error_line(capsys)


def test_corrupt_checkpoint_is_reported_and_kept(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.pt").write_bytes(b"\x80garbage")
    assert main(["evaluate", str(run)]) == 2
    assert "corrupt" in _one_error_line(capsys)
    assert (run / "checkpoint.pt").read_bytes() == b"\x80garbage"


def test_console_script_is_installed():
    exe = shutil.which("hubsgo") or str(__import__("pathlib").Path(sys.executable).parent / "hubsgo")
    res = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "train" in res.stdout


@pytest.mark.parametrize("setting, needles", [
    ("loop.nonsense=3", ["unknown key 'nonsense' in section 'loop'", "valid keys:", "option_steps"]),
    ("high.lrr=0.1", ["unknown key 'lrr' in section 'high'", "batch_size", "lr"]),
    ("low.total_steps=5", ["unknown key 'total_steps' in section 'low'", "learning_starts"]),
    ("loop.option_steps=many", ["loop.option_steps takes an integer >= 1 (default 10)", "'many'"]),   # the maze preset's
    ("high.double_q=maybe", ["high.double_q takes true or false"]),
    ("nonsense=3", ["unknown setting 'nonsense'", "sections:", "loop"]),
    ("loop=3", ["'loop' is a section"]),
    ("nosection.x=3", ["unknown section 'nosection'"]),
    ("env.nonsense=3", ["--set env.nonsense=3: unknown key 'nonsense' in section 'env' (task keydoor); valid keys: ",
                        "max_steps", "obs_mode", "start", "tile_size"]),
    ("env.start=anywhere", ["cannot be built with --set env.start=anywhere", "use 'cell' or 'room'"]),
    ("loop.filter_refresh=later", ["loop.filter_refresh takes one of 'option', 'episode' (default 'episode')"]),
    ("loop.outcome_window=-1", ["loop.outcome_window takes an integer >= 1 (default 20), got -1"]),
])
@pytest.mark.parametrize("agent", ["hubsgo", "hdqn"])
def test_bad_set_key_one_line_naming_section_and_valid_keys(setting, needles, agent, capsys, tmp_path):
    out = tmp_path / "runs" / "o"
    assert main(["train", "keydoor", "--agent", agent, "--out", str(out), "--no-progress", "--steps", "100",
                 "--set", setting]) == 2
    line = _one_error_line(capsys)
    for needle in needles:
        assert needle in line, (needle, line)
    assert not out.exists(), "a run that cannot be built left its --out folder behind"


def test_a_run_that_cannot_be_built_keeps_an_existing_out_folder(capsys, tmp_path):
    out = tmp_path / "o"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(["train", "keydoor", "--out", str(out), "--no-progress", "--steps", "100",
                 "--set", "env.start=anywhere"]) == 2
    assert "cannot be built" in _one_error_line(capsys)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]


HALL = "#######\n#A..#.#\n#.k.D.#\n#...#G#\n#######\n"     # a red key and its locked door before the goal


def _hall(folder, name="hall", layout=HALL):
    """A user's maze in ``folder``: ``NAME.txt`` and the catalogue ``NAME.yaml`` (sub-goals key, door,
    goal); returns the catalogue's path."""
    (folder / f"{name}.txt").write_text(layout)
    (folder / f"{name}.yaml").write_text(yaml.safe_dump({
        "task": name, "family": "minigrid",
        "options": {"layout": f"{name}.txt", "legend": {"k": {"type": "key", "color": "red"},
                                                          "D": {"type": "door", "color": "red", "locked": True}}},
        "subgoals": [{"name": "key", "kind": "carrying", "args": {"type": "key", "color": "red"}},
                     {"name": "door", "kind": "door_open", "args": {"color": "red"}},
                     {"name": "goal", "kind": "goal"}]}))
    return folder / f"{name}.yaml"


def test_a_user_maze_without_a_spec_asks_for_one_and_trains_with_one(capsys, tmp_path):
    _hall(tmp_path)
    out = tmp_path / "run"
    assert main(["train", str(tmp_path / "hall.yaml"), "--out", str(out), "--steps", "100", "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert "task 'hall' has no built-in critic spec hall-specific" in line and "--graph independent" in line
    assert not out.exists()
    edgeless = tmp_path / "edgeless"        # a graph that takes no edges needs no spec
    assert main(["train", str(tmp_path / "hall.yaml"), "--graph", "independent", "--out", str(edgeless),
                 "--steps", "200", "--no-progress", *TINY]) == 0
    assert "no --model: graph independent over the catalogue's 3 sub-goals" in capsys.readouterr().err
    cfg = yaml.safe_load((edgeless / "config.yaml").read_text())
    assert cfg["model"] == "hall-independent" and cfg["model_spec"]["graph"] == "independent"
    assert cfg["model_spec"]["subgoals"] == ["key", "door", "goal"] and cfg["model_spec"]["edges"] == []
    assert main(["train", str(tmp_path / "hall.yaml"), "--graph", "independent", "--out", str(edgeless),
                 "--steps", "800", "--resume", "--no-progress", *TINY]) == 0
    (tmp_path / "hall-spec.yaml").write_text(yaml.safe_dump({
        "name": "hall-spec", "task": "hall", "subgoals": ["key", "door", "goal"], "graph": "specific",
        "edges": [["key", "door", "positive"], ["door", "goal", "positive"]],
        "prior": {"name": "ising", "strength": 3.0, "field": -2.0}, "likelihood": {"name": "outcome"}}))
    assert main(["train", str(tmp_path / "hall.yaml"), "--model", str(tmp_path / "hall-spec.yaml"), "--out", str(out),
                 "--steps", "300", "--no-progress", *TINY]) == 0
    assert json.loads((out / "subgoals.json").read_text())["names"] == ["key", "door", "goal"]


def test_a_run_on_a_user_maze_given_by_a_relative_path_works_from_another_folder(capsys, tmp_path, monkeypatch):
    """The run's config names the catalogue by its absolute path: evaluate, review and resume from elsewhere."""
    mazes, elsewhere = tmp_path / "mazes", tmp_path / "elsewhere"
    mazes.mkdir()
    elsewhere.mkdir()
    _hall(mazes)
    (mazes / "hall-spec.yaml").write_text(yaml.safe_dump({
        "name": "hall-spec", "subgoals": ["key", "door", "goal"],
        "edges": [["key", "door", "positive"], ["door", "goal", "positive"]]}))
    run = tmp_path / "run"
    monkeypatch.chdir(mazes)
    assert main(["train", "hall.yaml", "--model", "hall-spec.yaml", "--out", str(run), "--steps", "400",
                 "--stop-at", "200", "--no-progress", *TINY]) == 0
    assert yaml.safe_load((run / "config.yaml").read_text())["task_ref"] == str(mazes / "hall.yaml")
    monkeypatch.chdir(elsewhere)
    capsys.readouterr()
    assert main(["train", "hall", "--out", str(run), "--resume", "--no-progress"]) == 0
    assert main(["evaluate", str(run), "--episodes", "1"]) == 0
    assert "hubsgo on hall: greedy return" in capsys.readouterr().out
    assert main(["review", str(run), "--no-gif"]) == 0
    assert "(episode " in capsys.readouterr().out
    review = json.loads((run / "review" / "review.json").read_text())
    assert review["task"] == "hall" and "settled_step" in review
    assert main(["train", "hall.yaml", "--out", str(tmp_path / "other"), "--no-progress"]) == 2
    assert _one_error_line(capsys) == (f"hubsgo: error: hall.yaml: no such task catalogue file (relative to "
                                       f"{elsewhere}); check the path, or pass a built-in task name (`hubsgo tasks` "
                                       "lists them)")
    # the layout edited after the run: read as it is now, with a warning; the catalogue gone: one line
    assert "warning" not in capsys.readouterr().err
    (mazes / "hall.txt").write_text("#######\n#A..#.#\n#.k.D.#\n#.#.#G#\n#######\n")
    assert main(["evaluate", str(run), "--episodes", "1"]) == 0
    assert (f"hubsgo: warning: {mazes / 'hall.yaml'} (or its layout) has changed since the run recorded it"
            in capsys.readouterr().err)
    (mazes / "hall.yaml").rename(mazes / "moved.yaml")
    assert main(["evaluate", str(run), "--episodes", "1"]) == 2
    assert _one_error_line(capsys) == (f"hubsgo: error: {mazes / 'hall.yaml'}: the run's task catalogue is no longer "
                                       "there; put it (and its layout) back at that path to read or resume the run")


def test_a_user_maze_whose_goal_cannot_be_reached_is_refused_before_a_run_starts(capsys, tmp_path):
    (tmp_path / "shut.txt").write_text("#######\n#A.#..#\n#.k#.G#\n#######\n")
    (tmp_path / "shut.yaml").write_text(yaml.safe_dump({
        "task": "shut", "family": "minigrid",
        "options": {"layout": "shut.txt", "legend": {"k": {"type": "key", "color": "red"}}},
        "subgoals": [{"name": "key", "kind": "carrying", "args": {"type": "key", "color": "red"}},
                     {"name": "goal", "kind": "goal"}]}))
    (tmp_path / "shut-spec.yaml").write_text(yaml.safe_dump({
        "name": "shut-spec", "subgoals": ["key", "goal"], "edges": [["key", "goal", "positive"]]}))
    out = tmp_path / "run"
    assert main(["train", str(tmp_path / "shut.yaml"), "--model", str(tmp_path / "shut-spec.yaml"), "--out", str(out),
                 "--steps", "100", "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert "shut.yaml: the goal (5, 2) cannot be reached from the start (1, 1)" in line
    assert not out.exists()


def test_a_user_maze_too_large_to_search_trains_with_a_note(capsys, tmp_path, monkeypatch):
    """Past its cap on states the exact search gives up; where the relaxation finds nothing wrong, one line says so."""
    from hubsgo_ppl.envs.minigrid import bfs

    real = bfs.check_reachable
    monkeypatch.setattr(bfs, "check_reachable", lambda source: real(source, max_states=1))
    (tmp_path / "open.txt").write_text("#####\n#A.G#\n#####\n")
    (tmp_path / "open.yaml").write_text(yaml.safe_dump({
        "task": "open", "family": "minigrid", "options": {"layout": "open.txt"},
        "subgoals": [{"name": "mid", "kind": "at", "args": {"cell": [2, 1]}}, {"name": "goal", "kind": "goal"}]}))
    (tmp_path / "open-spec.yaml").write_text(yaml.safe_dump({
        "name": "open-spec", "subgoals": ["mid", "goal"], "edges": [["mid", "goal", "positive"]]}))
    assert main(["train", str(tmp_path / "open.yaml"), "--model", str(tmp_path / "open-spec.yaml"),
                 "--out", str(tmp_path / "run"), "--steps", "50", "--no-progress", *TINY]) == 0
    notes = [line for line in capsys.readouterr().err.splitlines() if "too many states" in line]
    assert notes == [f"hubsgo: note: {tmp_path / 'open.yaml'}: the maze has too many states to check exactly "
                     "before training that its goal and sub-goals can be reached; a coarser check over its cells "
                     "found nothing wrong"]
    assert (tmp_path / "run" / "metrics.csv").exists()


def test_a_spec_that_leaves_out_the_goal_is_warned_in_train_and_in_revise(capsys, tmp_path):
    """Without the task's goal among the candidates the high level can never choose it: say so."""
    spec = tmp_path / "no-goal.yaml"
    spec.write_text(yaml.safe_dump({
        "name": "no-goal", "subgoals": ["yellow_key", "yellow_door", "blue_key"],
        "edges": [["yellow_key", "yellow_door", "positive"], ["yellow_key", "blue_key", "negative"]]}))
    warning = ("hubsgo: warning: model spec 'no-goal' leaves out goal (the task's goal): the high level can never "
               "choose it, so the agent reaches it only by chance")
    assert main(["train", "keydoor", "--model", str(spec), "--out", str(tmp_path / "a"), "--steps", "100",
                 "--no-progress", *TINY]) == 0
    assert [line for line in capsys.readouterr().err.splitlines() if "leaves out" in line][0].startswith(warning)
    run = tmp_path / "b"
    assert main(["train", "keydoor", "--out", str(run), "--steps", "300", "--stop-at", "100",
                 "--no-progress", *TINY]) == 0
    assert "leaves out" not in capsys.readouterr().err          # the shipped spec lists the goal
    assert main(["revise", str(run), "--model", str(spec), "--no-progress"]) == 0
    assert [line for line in capsys.readouterr().err.splitlines() if "leaves out" in line][0].startswith(warning)


def test_a_spec_that_leaves_the_goal_unlinked_gets_a_note_and_the_shipped_one_does_not(capsys, tmp_path):
    """With the default prior and evidence, a goal no positive edge reaches stays out of G*; say so."""
    spec = tmp_path / "keys-only.yaml"
    spec.write_text(yaml.safe_dump({
        "name": "keys-only", "subgoals": ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"],
        "edges": [["yellow_key", "yellow_door", "positive"], ["blue_key", "blue_door", "positive"],
                  ["yellow_key", "blue_key", "negative"]]}))
    assert main(["train", "keydoor", "--model", str(spec), "--out", str(tmp_path / "a"), "--steps", "100",
                 "--no-progress", *TINY]) == 0
    err = capsys.readouterr().err
    assert ("hubsgo: note: model spec 'keys-only' gives goal (the task's goal) no positive edge, so its prior's "
            "field keeps it out of G*") in err
    # the evidence at full weight (power 1: 3.9 nats) outweighs the field of -2: no note
    spec.write_text(spec.read_text() + "likelihood: {name: outcome, power: 1.0}\n")
    assert main(["train", "keydoor", "--model", str(spec), "--out", str(tmp_path / "b"), "--steps", "100",
                 "--no-progress", *TINY]) == 0
    assert "hubsgo: note" not in capsys.readouterr().err
    assert main(["train", "keydoor", "--out", str(tmp_path / "c"), "--steps", "100", "--no-progress", *TINY]) == 0
    assert "hubsgo: note" not in capsys.readouterr().err
    # a revision to such a spec gets the same note
    spec.write_text(spec.read_text().replace("likelihood: {name: outcome, power: 1.0}\n", ""))
    run = tmp_path / "d"
    assert main(["train", "keydoor", "--out", str(run), "--steps", "300", "--stop-at", "100", "--no-progress",
                 *TINY]) == 0
    capsys.readouterr()
    assert main(["revise", str(run), "--model", str(spec), "--no-train"]) == 0
    assert "hubsgo: note: model spec 'keys-only' gives goal (the task's goal) no positive edge" in capsys.readouterr().err


def test_missing_robosuite_names_the_extra(monkeypatch, capsys, tmp_path):
    for name in [m for m in sys.modules if m.startswith(("robosuite.", "mujoco.", "hubsgo_ppl.envs.robosuite"))]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "robosuite", None)      # as if not installed: importing it fails
    assert main(["train", "collect_three_balls", "--out", str(tmp_path / "o"), "--no-progress",
                 "--steps", "100"]) == 2
    line = _one_error_line(capsys)
    assert 'pip install "hubsgo-ppl[robosuite]"' in line and "collect_three_balls" in line


class _Marker:
    def __init__(self, path):
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


@pytest.mark.parametrize("verb", ["evaluate", "resume", "subgoals"])
def test_checkpoint_with_pickled_code_is_refused_in_one_line(verb, tmp_path, capsys):
    from hubsgo_ppl.experiments.io import save_torch

    run, marker = tmp_path / "run", tmp_path / "code-ran"
    save_torch(run / "checkpoint.pt", {"format": 1, "config": {"task": "keydoor"}, "agent": _Marker(marker)})
    argv = {"evaluate": ["evaluate", str(run)], "subgoals": ["subgoals", str(run), "--recompute"],
            "resume": ["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]}[verb]
    assert main(argv) == 2
    line = _one_error_line(capsys)
    assert "refusing to load" in line and "io.open" in line
    assert not marker.exists(), "the checkpoint's code ran"


def test_incomplete_checkpoint_is_refused_in_one_line(tmp_path, capsys):
    from hubsgo_ppl.experiments.io import save_torch

    save_torch(tmp_path / "run" / "checkpoint.pt", {"format": 1, "agent": {}})
    assert main(["evaluate", str(tmp_path / "run")]) == 2
    assert "not a checkpoint of a `hubsgo train` run (missing ['config'" in _one_error_line(capsys)


def test_resume_of_a_run_killed_before_its_first_checkpoint_starts_afresh(tmp_path, capsys):
    from hubsgo_ppl.experiments.run import RunConfig, resolve

    run = tmp_path / "run"
    (run / "tb").mkdir(parents=True)
    (run / "tb" / "events.out.tfevents.1.host.1.0").write_bytes(b"partial")
    (run / "config.yaml").write_text("task: keydoor\n")
    (run / "metrics.csv").write_text("episode,return\r\n0,0.5\r\n1,0.0\r\n")
    (run / ".metrics.csv.1a2b3c4d.tmp").write_text("left by a kill")
    args = ["train", "keydoor", "--out", str(run), "--resume", "--steps", "300", "--seed", "2", "--no-progress", *TINY]
    assert main(args) == 2          # a config.yaml that does not record a whole run: nothing to rebuild
    assert "config.yaml is missing or damaged" in _one_error_line(capsys)
    assert (run / "config.yaml").read_text() == "task: keydoor\n" and (run / "metrics.csv").is_file()
    overrides = [v for k, v in zip(TINY[::2], TINY[1::2])]
    (run / "config.yaml").write_text(yaml.safe_dump(resolve(RunConfig(task="keydoor", steps=300, seed=2,
                                                                      overrides=overrides))))
    assert main(args) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "afresh" in err[0] and str(run) in err[0], err
    rows = list(csv.DictReader((run / "metrics.csv").open(newline="")))
    assert [r["episode"] for r in rows] == [str(i) for i in range(len(rows))]
    assert "wall_time" in rows[0] and rows[-1]["env_steps"] and int(rows[-1]["env_steps"]) >= 300
    assert yaml.safe_load((run / "config.yaml").read_text())["seed"] == 2
    assert (run / "checkpoint.pt").is_file()
    assert not (run / "tb" / "events.out.tfevents.1.host.1.0").exists()
    assert not list(run.glob(".*.tmp"))


def _five_subgoal_spec(path):
    spec = yaml.safe_load(open(__import__("hubsgo_ppl.resources", fromlist=["models_dir"]).models_dir()
                               / "keydoor_incorrect-specific.yaml"))
    spec["name"] = "keydoor_incorrect-no-corners"
    spec["subgoals"] = spec["subgoals"][:5]
    path.write_text(yaml.safe_dump(spec))
    return path


def test_stop_at_review_revise_and_a_subset_spec_from_scratch(tmp_path, capsys):
    run, spec = tmp_path / "run", _five_subgoal_spec(tmp_path / "no-corners.yaml")
    assert main(["train", "keydoor_incorrect", "--steps", "900", "--stop-at", "300", "--seed", "0", "--out", str(run),
                 "--no-progress", *TINY]) == 0
    out = capsys.readouterr().out
    assert "paused before its budget" in out and "G* from" not in out
    assert main(["revise", str(run), "--model", str(spec), "--no-progress"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"revision 1 of {run} at env step ") and "-> keydoor_incorrect-no-corners" in out[0]
    assert "sub-goals dropped: corner_nw, corner_sw, corner_ne, corner_se; added: none" in out[1]
    # 300 steps bring no success, so the outcome critic has not updated: it starts as the revised spec says
    assert out[3].strip() == ("the critic had not updated yet, so it starts as the revised spec says (every factor "
                              "from its prior and signs); carried over by name: 5 high-level outputs")
    assert any(line.startswith(f"run: {run}  ") and "env_steps=" in line for line in out)
    marginals = [line for line in out if line.startswith("marginals P(w=1): ")]
    assert marginals and "corner" not in marginals[0] and "goal=" in marginals[0]
    rows = list(csv.DictReader((run / "revisions.csv").open(newline="")))
    assert len(rows) == 1 and rows[0]["subgoals_dropped"] == "corner_nw corner_sw corner_ne corner_se"

    fresh = tmp_path / "fresh"          # the corrected spec from scratch: the corners are no candidates
    assert main(["train", "keydoor_incorrect", "--model", str(spec), "--steps", "300", "--out", str(fresh),
                 "--no-progress", *TINY]) == 0
    captured = capsys.readouterr()
    assert "not candidates in this run: corner_nw, corner_sw, corner_ne, corner_se" in captured.err
    assert yaml.safe_load((fresh / "config.yaml").read_text())["subgoals"] == [
        "yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]


@pytest.mark.parametrize("argv, needle", [
    (["train", "keydoor", "--transfer", "critic"], "add --init-from RUN"),
    (["train", "keydoor", "--stop-at", "0"], "--stop-at must be a positive env step"),
    (["revise", "/nonexistent/run", "--model", "keydoor-specific"], "no such run directory"),
])
def test_revise_and_transfer_bad_input_one_line(argv, needle, capsys, tmp_path):
    if argv[0] == "train":
        argv = argv + ["--out", str(tmp_path / "o"), "--no-progress"]
    assert main(argv) == 2
    assert needle in _one_error_line(capsys)


@pytest.mark.parametrize("argv, line", [
    (["train", "keydoor", "--bogus", "3"], "unrecognized arguments: --bogus 3; see `hubsgo train --help`"),
    (["train", "keydoor", "--steps", "abc"], "argument --steps: invalid int value: 'abc'; see `hubsgo train --help`"),
    (["train"], "the following arguments are required: task; see `hubsgo train --help`"),
    (["trian", "keydoor"], "argument command: invalid choice: 'trian'"),
    (["train", "keydoor", "--seed", "-1"], "argument --seed: a seed is a whole number, 0 or more; got -1"),
    (["evaluate", "run", "--seed", "1.5"], "argument --seed: a seed is a whole number, 0 or more; got '1.5'"),
])
def test_a_command_line_argparse_refuses_gets_one_line(capsys, argv, line):
    assert main(argv) == 2
    assert line in _one_error_line(capsys)
    assert capsys.readouterr().out == ""


def test_train_checkpoints_every_checkpoint_steps_and_a_resumed_run_keeps_its_own(tmp_path):
    from hubsgo_ppl.experiments.io import load_checkpoint

    out = tmp_path / "run"
    args = ["train", "keydoor", "--out", str(out), "--steps", "400", "--no-progress", *TINY]
    assert main([*args, "--checkpoint-steps", "150", "--stop-at", "200"]) == 0
    assert yaml.safe_load((out / "config.yaml").read_text())["checkpoint_steps"] == 150
    paused = int(load_checkpoint(out / "checkpoint.pt")["agent"]["env_steps"])
    assert 200 <= paused < 400
    assert main([*args, "--resume"]) == 0          # the default would be 5,000; the run keeps 150
    assert yaml.safe_load((out / "config.yaml").read_text())["checkpoint_steps"] == 150


def test_resume_refuses_flags_that_would_change_the_run_and_keeps_config_yaml_with_the_checkpoint(tmp_path, capsys):
    run = tmp_path / "run"
    start = ["train", "keydoor", "--seed", "3", "--steps", "600", "--out", str(run), "--no-progress", *TINY]
    assert main([*start, "--stop-at", "200"]) == 0
    capsys.readouterr()
    for flags, needle in ((["--seed", "4"], "--seed 4 (the run's is 3)"),
                          (["--agent", "hdqn"], "--agent hdqn (the run's is hubsgo)"),
                          (["--set", "high.lr=0.5"], "--set high.lr=0.5 (the run's is 0.001)"),
                          (["--model", "keydoor-fully_connected"], "--model keydoor-fully_connected"),
                          (["--graph", "independent"], "--graph independent (the run's is specific"),
                          (["--steps", "100"], "the run has already taken")):
        assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress", *flags]) == 2, flags
        assert needle in _one_error_line(capsys)
    assert main(["train", "fourroom", "--out", str(run), "--resume", "--no-progress"]) == 2
    assert "task fourroom (the run's is keydoor)" in _one_error_line(capsys)
    # another task with its own spec: the task is what differs, not a spec read against the run's task
    assert main(["train", "fourroom", "--model", "fourroom-specific", "--out", str(run), "--resume",
                 "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert "task fourroom (the run's is keydoor)" in line and "sub-goal" not in line and "--model" not in line
    assert main(["train", "keydoor", "--out", str(tmp_path / "new"), "--steps", "500", "--set", "steps=300"]) == 2
    assert ("the budget is given twice, --steps 500 and --set steps=300; give it once"
            in _one_error_line(capsys))
    # the command that started the run, repeated with --resume, continues it to a longer budget
    assert main([*start[:5], "900", *start[6:], "--resume"]) == 0
    ckpt = torch.load(run / "checkpoint.pt", weights_only=False)
    assert ckpt["env_steps"] >= 900 and ckpt["config"]["hyper"]["steps"] == 900
    assert yaml.safe_load((run / "config.yaml").read_text())["hyper"]["steps"] == 900
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]) == 0    # nothing left to train
    assert "has finished its budget of 900 env steps; nothing to train" in capsys.readouterr().err


@pytest.mark.parametrize("setting, line", [
    ("loop.option_steps=0", "loop.option_steps takes an integer >= 1 (default 10), got 0"),
    ("loop.gamma=nan", "loop.gamma takes a number in [0, 1] (default 0.99), got 'nan'"),
    ("high.lr=inf", "high.lr takes a finite number > 0 (default 0.001), got 'inf'"),
    ("low.lr=0", "low.lr takes a finite number > 0 (default 0.0005), got 0"),
    ("high.hidden=[0]", "high.hidden takes a list of integers >= 1, e.g. [64, 64] (default [128, 128]), got [0]"),
    ("loop.explore_fraction=0", "loop.explore_fraction takes a number in (0, 1] (default 0.3), got 0"),
])
def test_a_setting_out_of_its_range_is_refused_before_the_run_starts(setting, line, capsys, tmp_path):
    out = tmp_path / "o"
    assert main(["train", "keydoor", "--set", setting, "--steps", "100", "--out", str(out), "--no-progress"]) == 2
    assert _one_error_line(capsys) == f"hubsgo: error: --set {setting}: {line}"
    assert not out.exists()


def test_a_run_whose_networks_diverge_ends_in_one_line(capsys, tmp_path):
    out = tmp_path / "o"
    assert main(["train", "keydoor", "--set", "high.lr=1e30", "--steps", "3000", "--out", str(out),
                 "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert "has NaN or inf entries" in line and "training diverged; it diverged before its first checkpoint" in line
    assert line.endswith("start a new run (another --out) with lower learning rates, e.g. --set high.lr=3e-4 "
                         "--set low.lr=1e-4")


@pytest.mark.parametrize("sweep_yaml, metrics, needle", [
    (None, None, "no such sweep directory"),
    ("- a list, not a sweep\n", "episode,env_steps,return,success\n1,10,0.5,1\n",
     "sweep.yaml: not the sweep file `hubsgo sweep` writes (TypeError"),
    (None, "episode,steps\n1,10\n", "metrics.csv: not a metrics file of `hubsgo train` ('return')"),
    (None, b"\xff\xfe\x00garbage", "metrics.csv: damaged, not a CSV log"),
])
def test_report_on_a_folder_that_is_not_a_sweep_gets_one_line(tmp_path, capsys, sweep_yaml, metrics, needle):
    folder = tmp_path / "sweep"
    if metrics is not None:
        run = folder / "keydoor" / "hdqn" / "seed0"
        run.mkdir(parents=True)
        (run / "metrics.csv").write_bytes(metrics if isinstance(metrics, bytes) else metrics.encode())
    if sweep_yaml is not None:
        (folder / "sweep.yaml").write_text(sweep_yaml)
    assert main(["report", str(folder)]) == 2
    assert needle in _one_error_line(capsys)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    run = tmp_path_factory.mktemp("tiny") / "run"
    assert main(["train", "keydoor", "--steps", "600", "--seed", "1", "--out", str(run), "--no-progress",
                 "--checkpoint-steps", "200", *TINY]) == 0
    return run


BINARY = b"\xff\xfe\x00\x01garbage"


@pytest.mark.parametrize("name, content, verb, expect", [
    ("metrics.csv", BINARY, ["review", "RUN", "--no-gif"], "metrics.csv: damaged, not a CSV log"),
    ("metrics.csv", b"a,b\n1,2\n", ["review", "RUN", "--no-gif"], "metrics.csv: damaged, its header lacks episode"),
    ("metrics.csv", BINARY, ["train", "keydoor", "--out", "RUN", "--resume", "--steps", "900"],
     "metrics.csv: damaged, not a CSV log"),
    # emptied or cut short: the checkpoint counts episodes whose rows are gone, and resuming would lose them
    ("metrics.csv", b"", ["train", "keydoor", "--out", "RUN", "--resume", "--steps", "900"],
     "metrics.csv: damaged: it holds 0 of the "),
    ("metrics.csv", b"episode,env_steps,length,success\n0,150,150,0\n", ["train", "keydoor", "--out", "RUN",
                                                                          "--resume", "--steps", "900"],
     "metrics.csv: damaged: it holds 1 of the "),
    ("metrics.csv", b"", ["revise", "RUN", "--model", "keydoor-specific", "--steps", "900"],
     "metrics.csv: damaged: it holds 0 of the "),
    ("critic_history.csv", BINARY, ["diagnose", "RUN", "--chains", "2", "--draws", "50", "--burn-in", "5"],
     "critic_history.csv: damaged, not a CSV log"),
    ("critic_history.csv", BINARY, ["train", "keydoor", "--out", "RUN", "--resume", "--steps", "900"],
     "critic_history.csv: damaged, not a CSV log"),
    ("tb", None, ["train", "keydoor", "--out", "RUN", "--resume", "--steps", "900"],
     "tb: a file where the TensorBoard folder goes; move it away"),
    ("config.yaml", BINARY, ["review", "RUN", "--no-gif"], None),       # the checkpoint's copy serves
    ("config.yaml", BINARY, ["revise", "RUN", "--model", "keydoor-specific", "--steps", "900"], None),
    ("subgoals.json", b"{not json", ["subgoals", "RUN"], None),        # recomputed from the checkpoint
    ("subgoals.json", BINARY, ["subgoals", "RUN"], None),
])
def test_a_damaged_run_file_gets_one_line_or_is_read_around(tiny_run, tmp_path, capsys, name, content, verb, expect):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    target = run / name
    if target.is_dir():
        shutil.rmtree(target)
    target.write_bytes(content if content is not None else b"")
    capsys.readouterr()
    code = main([str(run) if a == "RUN" else a for a in verb] + (["--no-progress"] if verb[0] in ("train", "revise") else []))
    if expect is None:
        assert code == 0, capsys.readouterr().err
        if name == "subgoals.json":
            captured = capsys.readouterr()
            assert "is damaged; G* is recomputed from the checkpoint" in captured.err
            assert captured.out.startswith("G* from 10,000 critic samples")
    else:
        assert code == 2
        assert expect in _one_error_line(capsys)
        assert target.read_bytes() == (content if content is not None else b"")     # nothing is lost


def test_a_resume_without_metrics_csv_goes_on_and_says_whose_rows_are_missing(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    (run / "metrics.csv").unlink()
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--steps", "900", "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert f"hubsgo: note: {run / 'metrics.csv'} is missing: the run goes on without the rows of its first" in err


def test_an_error_no_check_names_gets_one_line_and_its_traceback_on_request(monkeypatch, capsys):
    from hubsgo_ppl.cli import tasks

    def broken(args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(tasks, "cmd_tasks", broken)
    monkeypatch.delenv("HUBSGO_TRACEBACK", raising=False)
    assert main(["tasks"]) == 1
    line = _one_error_line(capsys)
    assert line.startswith("hubsgo: error: unexpected ZeroDivisionError: float division by zero (in test_cli.py, line ")
    assert line.endswith("HUBSGO_TRACEBACK=1 shows the traceback")
    monkeypatch.setenv("HUBSGO_TRACEBACK", "1")
    with pytest.raises(ZeroDivisionError):
        main(["tasks"])


def test_a_folder_that_cannot_be_written_gets_one_line_naming_the_file(monkeypatch, capsys):
    from hubsgo_ppl.cli import tasks

    def denied(args):
        raise PermissionError(1, "Operation not permitted", "runs/kd/.eval.json.b1a5.tmp")

    monkeypatch.setattr(tasks, "cmd_tasks", denied)
    assert main(["tasks"]) == 2
    assert _one_error_line(capsys) == ("hubsgo: error: runs/kd/.eval.json.b1a5.tmp: Operation not permitted; check the "
                                      "folder's permissions and free space")


def test_a_transfer_to_a_users_maze_without_a_spec_takes_the_source_runs(capsys, tmp_path):
    hall = str(_hall(tmp_path))
    moved = str(_hall(tmp_path, "hall_moved", "#######\n#Ak.#.#\n#...D.#\n#...#G#\n#######\n"))
    (tmp_path / "hall-spec.yaml").write_text(yaml.safe_dump({
        "name": "hall-spec", "subgoals": ["key", "door", "goal"],
        "edges": [["key", "door", "positive"], ["door", "goal", "positive"]]}))
    src = tmp_path / "src"
    assert main(["train", hall, "--model", str(tmp_path / "hall-spec.yaml"), "--out", str(src), "--steps", "300",
                 "--no-progress", *TINY]) == 0
    assert main(["train", moved, "--out", str(tmp_path / "dst"), "--steps", "200", "--no-progress"]) == 2
    assert "has no built-in critic spec" in _one_error_line(capsys)
    # a source that is not there is named as such, not as a missing spec
    assert main(["train", moved, "--init-from", str(tmp_path / "nowhere"), "--out", str(tmp_path / "dst"),
                 "--steps", "200", "--no-progress"]) == 2
    assert _one_error_line(capsys).startswith(f"hubsgo: error: --init-from {tmp_path / 'nowhere'}: no such run directory")
    # a source that trained no critic has no spec to take: said so
    assert main(["train", hall, "--agent", "hdqn", "--out", str(tmp_path / "plain"), "--steps", "200",
                 "--no-progress", *TINY]) == 0
    capsys.readouterr()
    assert main(["train", moved, "--init-from", str(tmp_path / "plain"), "--out", str(tmp_path / "dst"),
                 "--steps", "200", "--no-progress"]) == 2
    assert "trained no critic to take one from: pass --model" in _one_error_line(capsys)
    assert main(["train", moved, "--init-from", str(src), "--out", str(tmp_path / "dst"), "--steps", "200",
                 "--no-progress", *TINY]) == 0
    assert "hubsgo: note: no --model: the critic spec of the --init-from run, 'hall-spec'" in capsys.readouterr().err
    cfg = yaml.safe_load((tmp_path / "dst" / "config.yaml").read_text())
    assert cfg["model"] == "hall-spec" and cfg["init_from"]["parts"] == ["critic", "high", "low"]


def test_tasks_gives_the_range_of_shortest_solutions_where_the_start_direction_is_random(capsys):
    """FourRoom draws its start direction each episode: the shortest solution depends on it (23 steps
    facing two of the ways, 24 the other two), and the check reports both ends instead of failing."""
    from hubsgo_ppl.envs.minigrid.bfs import optimal_steps, optimal_steps_range

    assert sorted(optimal_steps("fourroom", start_dir=d) for d in range(4)) == [23, 23, 24, 24]
    assert optimal_steps_range("fourroom") == (23, 24) and optimal_steps_range("keydoor") == (19, 19)
    assert main(["tasks", "fourroom_incorrect", "--model", "fourroom_incorrect-believed"]) == 0
    out = capsys.readouterr().out
    assert ("    reachability: the goal and every sub-goal can be reached; shortest solution 23-24 steps, by the start "
            "direction (drawn at random each episode)") in out.splitlines()


def test_tasks_checks_a_catalogue_and_a_spec_without_training(capsys, tmp_path):
    _hall(tmp_path)
    spec = tmp_path / "hall-spec.yaml"
    spec.write_text(yaml.safe_dump({"name": "hall-spec", "subgoals": ["key", "door", "goal"],
                                    "edges": [["key", "door", "positive"], ["door", "goal", "positive"]]}))
    hall = str(tmp_path / "hall.yaml")
    assert main(["tasks", hall, "--model", str(spec)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"{hall}  (minigrid") and "    - door [door_open]" in out
    assert "    reachability: the goal and every sub-goal can be reached; shortest solution 11 steps" in out
    assert out[-1] == ("    critic spec 'hall-spec': 3 sub-goals, 2 edges, prior ising, likelihood outcome: valid for "
                       "this task")
    assert not list(tmp_path.glob("runs")) and not (tmp_path / "runs").exists()
    assert main(["tasks", hall]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "    critic spec: none built in for this task; check yours with --model SPEC"
    # what train warns of a spec, the check warns of too: here a goal no positive edge reaches
    spec.write_text(yaml.safe_dump({"name": "keys", "subgoals": ["key", "door", "goal"],
                                    "edges": [["key", "door", "positive"]]}))
    assert main(["tasks", hall, "--model", str(spec)]) == 0
    assert "hubsgo: note: model spec 'keys' gives goal (the task's goal) no positive edge" in capsys.readouterr().err
    # the key behind its own door: refused as `hubsgo train` refuses it
    (tmp_path / "hall.txt").write_text("#######\n#A..#k#\n#...D.#\n#...#G#\n#######\n")
    assert main(["tasks", hall, "--model", str(spec)]) == 2
    assert "cannot be reached" in _one_error_line(capsys)
    assert main(["tasks", "--model", str(spec)]) == 2
    assert "--model checks a spec against the tasks named" in _one_error_line(capsys)


def test_flags_and_spec_keys_that_would_be_ignored_are_refused_or_noted(capsys, tmp_path):
    assert main(["train", "keydoor", "--agent", "hdqn", "--graph", "independent", "--out", str(tmp_path / "a"),
                 "--steps", "100", "--no-progress"]) == 2
    assert ("--graph independent sets the critic's graph, and agent 'hdqn' has no critic"
            in _one_error_line(capsys))
    spec = tmp_path / "s.yaml"
    spec.write_text(yaml.safe_dump({"name": "s", "task": "fourroom", "graph": "independent",
                                    "subgoals": ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"],
                                    "edges": [["yellow_door", "goal", "positive"]]}))
    assert main(["train", "keydoor", "--model", str(spec), "--out", str(tmp_path / "b"), "--steps", "100",
                 "--no-progress", *TINY]) == 0
    err = capsys.readouterr().err
    assert "hubsgo: note: model spec 's' names task 'fourroom'; it is used for 'keydoor'" in err
    assert "hubsgo: note: model spec 's' has graph independent, so its edges (1) are not used" in err
    # a file where the run's folder goes
    (tmp_path / "afile").write_text("x")
    assert main(["train", "keydoor", "--out", str(tmp_path / "afile"), "--steps", "100", "--no-progress"]) == 2
    assert f"--out {tmp_path / 'afile'}: a file, not a folder" in _one_error_line(capsys)


def test_diagnose_revise_and_init_from_bad_values_get_one_line(tiny_run, tmp_path, capsys):
    for argv, line in ((["diagnose", str(tiny_run), "--draws", "0"], "--draws must be at least 2, got 0"),
                       (["diagnose", str(tiny_run), "--burn-in", "-1"], "--burn-in must be at least 0, got -1"),
                       (["revise", str(tiny_run), "--model", "keydoor-specific", "--steps", "-5", "--no-train"],
                        "--steps must be a positive number of env steps, got -5")):
        assert main(argv) == 2
        assert _one_error_line(capsys) == f"hubsgo: error: {line}"
    broken = tmp_path / "broken"
    shutil.copytree(tiny_run, broken)
    (broken / "checkpoint.pt").write_bytes(b"garbage")
    assert main(["train", "keydoor", "--init-from", str(broken), "--out", str(tmp_path / "o"), "--steps", "300",
                 "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert "checkpoint is corrupt or unreadable" in line
    assert line.endswith("; start from another run, or train without --init-from")


def test_revise_refuses_stop_at_with_no_train_and_leaves_the_run_as_it_was(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    ckpt = (run / "checkpoint.pt").read_bytes()
    assert main(["revise", str(run), "--model", "keydoor-specific", "--steps", "900", "--no-train",
                 "--stop-at", "700"]) == 2
    assert "--stop-at pauses the training after the revision, and --no-train trains nothing" in _one_error_line(capsys)
    assert (run / "checkpoint.pt").read_bytes() == ckpt and not (run / "revisions").exists()


def test_a_revision_that_changes_nothing_is_recorded_with_a_note(tiny_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)
    assert main(["revise", str(run), "--model", "keydoor-specific", "--steps", "900", "--no-train"]) == 0
    assert "asks for the critic the run already has; it is recorded as revision 1" in capsys.readouterr().err


def test_a_users_catalogue_named_like_a_built_in_task_says_which_spec_it_gets(capsys, tmp_path):
    from hubsgo_ppl.resources import envs_dir

    data = yaml.safe_load((envs_dir() / "keydoor.yaml").read_text())
    layout = data["options"]["layout"]
    shutil.copy(envs_dir() / layout, tmp_path / layout)
    (tmp_path / "mine.yaml").write_text(yaml.safe_dump(data))
    assert main(["train", str(tmp_path / "mine.yaml"), "--out", str(tmp_path / "run"), "--steps", "100",
                 "--no-progress", *TINY]) == 0
    assert ("hubsgo: note: no --model: the built-in spec 'keydoor-specific', named after the catalogue's task "
            "'keydoor'; pass --model to use your own") in capsys.readouterr().err


def test_resume_restores_config_yaml_and_refuses_to_start_over_a_run_whose_checkpoint_is_lost(tiny_run, tmp_path,
                                                                                               capsys):
    run = tmp_path / "run"
    shutil.copytree(tiny_run, run)       # 600 steps, a checkpoint every 200
    (run / "config.yaml").unlink()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--steps", "900", "--no-progress"]) == 0
    assert yaml.safe_load((run / "config.yaml").read_text())["hyper"]["steps"] == 900
    (run / "checkpoint.pt").unlink()
    rows = (run / "metrics.csv").read_text()
    capsys.readouterr()
    assert main(["train", "keydoor", "--out", str(run), "--resume", "--no-progress"]) == 2
    line = _one_error_line(capsys)
    assert "checkpoint.pt is missing, though metrics.csv reaches env step" in line and "put the checkpoint back" in line
    assert (run / "metrics.csv").read_text() == rows          # nothing removed


def test_a_run_read_after_its_layout_changed_says_so_rather_than_call_the_checkpoint_damaged(capsys, tmp_path):
    _hall(tmp_path)
    run = tmp_path / "run"
    assert main(["train", str(tmp_path / "hall.yaml"), "--agent", "hdqn", "--out", str(run), "--steps", "200",
                 "--no-progress", *TINY]) == 0
    (tmp_path / "hall.txt").write_text("########\n#A..#..#\n#.k.D..#\n#...#G.#\n########\n")      # a wider grid
    capsys.readouterr()
    assert main(["evaluate", str(run), "--episodes", "1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("hubsgo: warning: ") and "has changed since the run recorded it" in err[0]
    assert err[1].endswith("which has changed since the run recorded it; put the catalogue and its layout back as "
                           "they were")


def test_every_option_of_every_command_has_help():
    import argparse

    from hubsgo_ppl.cli import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert {"train", "revise", "evaluate", "subgoals", "diagnose", "sweep", "report", "review", "render",
            "tasks"} <= set(commands.choices)
    for name, sub in commands.choices.items():
        for action in sub._actions:
            assert action.help and action.help != argparse.SUPPRESS, (name, action.option_strings or action.dest)
    text = commands.choices["diagnose"].format_help()
    for option in ("--chains", "--draws", "--burn-in"):
        assert next(line for line in text.splitlines() if line.strip().startswith(option)).split(maxsplit=2)[2:]


def test_the_cli_package_loads_nothing_heavy_and_no_module_is_long():
    """Importing the entry point loads only the standard library (the commands import what they use when they
    run), so Ctrl-C during start-up reaches main's handler; and each module of the package stays short."""
    import hubsgo_ppl.cli as cli

    code = "import sys, hubsgo_ppl.cli; print(sorted(m for m in ('numpy', 'torch', 'pydantic') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(cli.__file__).parents[2])
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr
    for module in Path(cli.__file__).parent.glob("*.py"):
        assert len(module.read_text().splitlines()) <= 450, module.name


_INTERRUPT = """
import sys
import hubsgo_ppl.cli.{module} as where
def interrupted(*args, **kwargs):
    raise KeyboardInterrupt
where.{name} = interrupted
from hubsgo_ppl.cli import main
sys.exit(main({argv!r}))
"""


@pytest.mark.parametrize("module, name, argv", [
    ("entry", "build_parser", ["train", "keydoor", "--steps", "1", "--out", "runs/y"]),     # start-up
    ("readouts", "cmd_review", ["review", "runs/x"]),
    ("readouts", "format_ranking", ["subgoals", "runs/x"]),    # the final G* table
])
def test_ctrl_c_anywhere_is_one_line_and_exit_2(module, name, argv, tmp_path):
    (tmp_path / "runs" / "x").mkdir(parents=True)
    (tmp_path / "runs" / "x" / "subgoals.json").write_text(json.dumps(
        {"num_samples": 10, "marginals": {"a": 0.5}, "ranking": [{"subgoals": ["a"], "prob": 0.5}]}))
    root = str(Path(__file__).resolve().parents[1])        # this checkout's package, from any folder
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}
    res = subprocess.run([sys.executable, "-c", _INTERRUPT.format(module=module, name=name, argv=argv)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert res.returncode == 2, res.stderr
    assert res.stderr.strip() == f"hubsgo: interrupted (Ctrl-C) during `hubsgo {argv[0]}`", res.stderr


def test_a_file_that_is_not_a_spec_given_as_model_is_not_printed_back(tmp_path, capsys):
    secret = tmp_path / "passwd"
    secret.write_text("rootpw: x:0:0:rootpw:/rootpw:/bin/bash\nhunter2: x:1:1::/usr/sbin:/usr/sbin/nologin\n")
    out = tmp_path / "run"
    for argv in (["train", "keydoor", "--model", str(secret), "--out", str(out), "--no-progress"],
                 ["tasks", "keydoor", "--model", str(secret)]):
        assert main(argv) == 2
        line = _one_error_line(capsys)
        assert line.startswith(f"hubsgo: error: {secret}: not a critic spec: a critic spec is a YAML mapping with the "
                               "keys name, task, subgoals"), line
        assert "rootpw" not in line and "hunter2" not in line and "/bin/bash" not in line
    assert not out.exists()


@pytest.mark.parametrize("budget", [["--steps", "0"], ["--set", "steps=0"], ["--set", "steps=-5"]])
def test_a_budget_of_no_steps_is_refused_the_same_way_by_flag_and_by_set(budget, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "fourroom", "--agent", "hdqn", "--out", str(out), "--no-progress", *budget]) == 2
    line = _one_error_line(capsys)
    assert "steps" in line and budget[-1].split("=")[-1] in line, line
    assert not out.exists()


def test_a_stop_at_that_could_not_pause_the_run_is_refused(tmp_path, capsys):
    """Past the budget (the run ends there anyway), or at or before the step a resumed run has reached."""
    run = tmp_path / "run"
    start = ["train", "keydoor", "--low-level", "scripted", "--steps", "300", "--out", str(run), "--no-progress"]
    assert main([*start, "--stop-at", "5000"]) == 2
    assert ("--stop-at 5000 is past the run's budget of 300 env steps, where it ends anyway"
            in _one_error_line(capsys))
    assert not run.exists()
    assert main([*start, "--stop-at", "100"]) == 0
    capsys.readouterr()
    done = torch.load(run / "checkpoint.pt", weights_only=False)["env_steps"]
    assert 100 <= done < 300
    metrics = (run / "metrics.csv").read_bytes()
    for stop, needle in ((done, f"has already taken {done:,} env steps; give a step above {done}"),
                         (301, "--stop-at 301 is past the run's budget of 300 env steps")):
        assert main([*start, "--resume", "--stop-at", str(stop)]) == 2
        assert needle in _one_error_line(capsys)
    assert (run / "metrics.csv").read_bytes() == metrics
    assert main([*start, "--resume", "--steps", "600", "--stop-at", "450"]) == 0       # inside a raised budget
    assert torch.load(run / "checkpoint.pt", weights_only=False)["env_steps"] >= 450


def test_a_fully_connected_critic_without_a_spec_of_ones_own_says_it_has_no_edges(tmp_path, capsys):
    """--graph fully_connected on a catalogue without a spec: every pair has a coupling, none an edge of
    the user's; a critic that never updated says its sets are the prior's alone, in train and subgoals."""
    import yaml

    (tmp_path / "m.txt").write_text("#######\n#A....#\n#....G#\n#######\n")
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "task": "m", "family": "minigrid", "options": {"layout": "m.txt", "max_steps": 3},     # no episode succeeds
        "subgoals": [{"name": "goal", "kind": "goal"}, {"name": "right", "kind": "at", "args": {"cell": [5, 1]}}]}))
    run = tmp_path / "run"
    assert main(["train", str(tmp_path / "m.yaml"), "--graph", "fully_connected", "--steps", "12", "--out", str(run),
                 "--no-progress"]) == 0
    assert json.loads((run / "subgoals.json").read_text())["spec_edges"] == 0
    said = "these sets are its prior's (the spec has no edges, so the prior alone)"
    assert said in capsys.readouterr().out.strip().splitlines()[-1]
    assert main(["subgoals", str(run)]) == 0
    assert said in capsys.readouterr().out.strip().splitlines()[-1]
