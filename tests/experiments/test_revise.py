"""`hubsgo revise`: a run continues with a revised critic spec; what persists is carried over bit for bit,
what is new starts where the prior says, sub-goals the catalogue lacks are refused, and a revised run is
deterministic."""

import csv
import shutil

import numpy as np
import pytest
import torch
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments.io import load_checkpoint
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.revise import apply_revision, revise
from hubsgo_ppl.experiments.run import RunConfig, RunError, load_run, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]
FIVE = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]
CORNERS = ["corner_nw", "corner_sw", "corner_ne", "corner_se"]
EDGES = [["yellow_key", "yellow_door", "positive"], ["blue_key", "blue_door", "positive"],
         ["yellow_key", "blue_key", "negative"], ["yellow_door", "blue_door", "negative"],
         ["yellow_door", "goal", "positive"], ["blue_door", "goal", "positive"]]
STEPS, PAUSE = 2400, 900


def _spec(path, name, subgoals, edges, likelihood=None):
    # a TD likelihood, so that the critic learns from the first high-level minibatch (no success needed)
    path.write_text(yaml.safe_dump({
        "name": name, "subgoals": subgoals, "graph": "specific", "edges": edges,
        "prior": {"name": "ising", "strength": 3.0, "field": -2.0},
        "likelihood": likelihood or {"name": "gaussian"},
        "inference": {"lr": 0.05, "burn_in": 8, "num_samples": 32, "kernel": "single_site", "init": "prior"}}))
    return path


@pytest.fixture(scope="module")
def paused(tmp_path_factory):
    """A keydoor_incorrect run (all nine sub-goals) paused at a third of its budget, its critic updated."""
    root = tmp_path_factory.mktemp("revise")
    spec = _spec(root / "initial.yaml", "initial", FIVE + CORNERS, EDGES)
    run = root / "run"
    train(RunConfig(task="keydoor_incorrect", model=str(spec), steps=STEPS, seed=1, checkpoint_steps=100,
                    overrides=TINY), run, progress=False, stop_at=PAUSE)
    return run


def _copy(paused, tmp_path, name="run"):
    out = tmp_path / name
    shutil.copytree(paused, out)
    return out


def _last(state):
    keys = sorted((k for k in state if k.endswith(".weight")), key=lambda k: int(k.split(".")[0]))
    return keys[-1], keys[-1].replace("weight", "bias")


def _edges(critic):
    return {frozenset((u, v)): float(j) for (u, v, _), j in zip(critic["edges"], critic["coupling"])}


def test_revise_round_trip_keeps_persisting_factors_and_outputs_bit_for_bit(paused, tmp_path):
    run = _copy(paused, tmp_path)
    before = load_checkpoint(run / "checkpoint.pt")
    old_critic, old_high, old_low = before["agent"]["filter"]["critic"], before["agent"]["high"], before["agent"]["low"]
    assert old_critic["num_updates"] > 0 and before["env_steps"] < STEPS
    assert not torch.equal(old_critic["theta"], torch.full((9,), -2.0)), "the critic must have learned something"

    # drop the corners, re-sign yellow_door--blue_door, drop blue_door--goal, add yellow_key--goal
    edges = [e for e in EDGES if e[:2] != ["blue_door", "goal"] and e[:2] != ["yellow_door", "blue_door"]]
    edges += [["blue_door", "yellow_door", "positive"], ["goal", "yellow_key", "positive"]]
    spec = _spec(tmp_path / "revised.yaml", "revised", ["goal", *FIVE[:4]], edges)      # any order
    record = apply_revision(run, spec)
    assert record["subgoals_dropped"] == CORNERS and record["subgoals_added"] == []
    assert record["edges_added"] == ["goal--yellow_key"] and record["edges_dropped"] == ["blue_door--goal"]
    assert record["edges_resigned"] == ["blue_door--yellow_door:negative->positive"]

    after = load_checkpoint(run / "checkpoint.pt")
    critic, high, low = after["agent"]["filter"]["critic"], after["agent"]["high"], after["agent"]["low"]
    assert critic["names"] == FIVE                                  # the catalogue's order
    for j, name in enumerate(FIVE):                                  # unary factors, bit for bit
        assert torch.equal(critic["theta"][j], old_critic["theta"][old_critic["names"].index(name)]), name
    old_j, new_j = _edges(old_critic), _edges(critic)
    for pair in (p for p in new_j if p in old_j):                   # persisting (and re-signed) couplings
        assert new_j[pair] == old_j[pair], pair
    assert new_j[frozenset(("yellow_key", "goal"))] == 3.0          # new edge: the ising prior's strength * sign
    assert frozenset(("blue_door", "goal")) not in new_j and len(new_j) == 6
    # the objective changed: the critic's optimiser and baseline restart, and the low level's goal weights
    assert critic["optimizer"]["state"] == {} and critic["baseline"] == {} and record["critic_optimizer"] == "restarted"

    w, b = _last(old_high["q"])
    rows = [old_critic["names"].index(n) for n in FIVE]
    for net in ("q", "q_target"):                                   # Q outputs of persisting sub-goals
        assert torch.equal(high[net][w], old_high[net][w][rows]) and torch.equal(high[net][b], old_high[net][b][rows])
        for k in old_high[net]:
            if k not in (w, b):
                assert torch.equal(high[net][k], old_high[net][k]), k
    lw, lb = _last(old_low["q"])
    blocks = torch.cat([torch.arange(i * 5, i * 5 + 5) for i in rows])      # 5 actions per goal
    assert torch.equal(low["q"][lw], old_low["q"][lw][blocks]) and torch.equal(low["q"][lb], old_low["q"][lb][blocks])
    assert old_low["goal_weight"] is not None and low["goal_weight"] is None

    # the high level's replay: transitions towards a corner removed, goals renumbered, masks remapped
    old_goals = old_high["buffer"]["data"]["goal"][:old_high["buffer"]["size"]]
    kept = np.isin(old_goals, rows)
    assert 0 < kept.sum() < len(old_goals)
    new_goals = high["buffer"]["data"]["goal"][:high["buffer"]["size"]]
    assert high["buffer"]["size"] == kept.sum()
    assert [FIVE[g] for g in new_goals] == [old_critic["names"][g] for g in old_goals[kept]]
    assert high["buffer"]["data"]["available"].shape[1] == 5 and low["buffer"]["data"]["before"].shape[1] == 5
    assert after["env_steps"] == before["env_steps"] and after["agent"]["rng"] == before["agent"]["rng"]

    cfg = yaml.safe_load((run / "config.yaml").read_text())
    assert cfg["subgoals"] == FIVE and cfg["revision"] == 1 and cfg["model"] == "revised"
    folder = run / "revisions" / "001"
    assert yaml.safe_load((folder / "spec_before.yaml").read_text())["subgoals"] == FIVE + CORNERS
    assert yaml.safe_load((folder / "spec_after.yaml").read_text())["subgoals"] == FIVE
    line = read_csv_rows(run / "revisions.csv")
    assert len(line) == 1 and int(line[0]["env_steps"]) == before["env_steps"]
    _, env, agent, _ = load_run(run)
    assert list(env.unwrapped.subgoal_names) == FIVE and agent.high.n_goals == 5
    env.close()

    # a second revision adds corner_nw back: it starts where the prior says
    spec2 = _spec(tmp_path / "again.yaml", "again", FIVE + ["corner_nw"], edges + [["corner_nw", "goal", "negative"]])
    record2 = apply_revision(run, spec2)
    assert record2["revision"] == 2 and record2["subgoals_added"] == ["corner_nw"]
    third = load_checkpoint(run / "checkpoint.pt")
    c3, h3 = third["agent"]["filter"]["critic"], third["agent"]["high"]
    assert c3["names"] == FIVE + ["corner_nw"]
    assert torch.equal(c3["theta"][:5], critic["theta"]) and float(c3["theta"][5]) == -2.0     # the prior's field
    assert _edges(c3)[frozenset(("corner_nw", "goal"))] == -3.0
    assert torch.equal(h3["q"][w][:5], high["q"][w]) and torch.equal(h3["q"][b][:5], high["q"][b])
    assert torch.allclose(h3["q"][w][5], high["q"][w].mean(0)) and torch.allclose(h3["q"][b][5], high["q"][b].mean())
    assert not third["agent"]["filter"]["outcomes"].shape[0]        # no stored episode says whether it was achieved
    assert [int(r["revision"]) for r in read_csv_rows(run / "revisions.csv")] == [1, 2]


def test_a_revision_that_changes_nothing_continues_the_run_as_if_unrevised(paused, tmp_path):
    """The same spec again: every part of the agent carries over (the critic's optimiser and baseline and
    the low level's goal weights included), so the run goes on exactly as its unrevised copy. A spec
    that differs in its name only changes nothing either."""
    state = load_checkpoint(paused / "checkpoint.pt")["agent"]
    assert state["filter"]["critic"]["optimizer"]["state"] and state["low"]["goal_weight"] is not None
    unrevised, revised = _copy(paused, tmp_path, "unrevised"), _copy(paused, tmp_path, "revised")
    spec = yaml.safe_load((paused.parent / "initial.yaml").read_text())
    renamed = tmp_path / "renamed.yaml"
    renamed.write_text(yaml.safe_dump({**spec, "name": "initial-reviewed"}))
    record = revise(revised, renamed, progress=False)["revision"]
    assert record["critic_optimizer"] == "carried over"
    train(RunConfig(task="keydoor_incorrect"), unrevised, resume=True, progress=False)

    def rows(run):
        return [{k: v for k, v in r.items() if k != "wall_time"} for r in read_csv_rows(run / "metrics.csv")]

    assert len(rows(unrevised)) > record["episode"] + 5
    assert rows(revised) == rows(unrevised)


def test_a_sub_goal_the_catalogue_lacks_is_refused_in_one_line(paused, tmp_path, capsys):
    run = _copy(paused, tmp_path)
    ckpt = (run / "checkpoint.pt").read_bytes()
    bad = _spec(tmp_path / "bad.yaml", "bad", ["yellow_key", "yellow_door", "red_key", "goal"], [])
    assert main(["revise", str(run), "--model", str(bad), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    assert "'red_key'" in err[0] and "not in the task's catalogue" in err[0]
    assert "yellow_key, yellow_door, blue_key, blue_door, goal, corner_nw" in err[0]
    assert (run / "checkpoint.pt").read_bytes() == ckpt and not (run / "revisions").exists()
    with pytest.raises(RunError, match="already taken"):
        apply_revision(run, _spec(tmp_path / "ok.yaml", "ok", FIVE, EDGES), steps=PAUSE // 2)


def test_a_resumed_revised_run_is_deterministic(paused, tmp_path):
    spec = _spec(tmp_path / "revised.yaml", "revised", FIVE, EDGES)
    again = tmp_path / "again"              # the same seeded run, trained to the same step anew
    train(RunConfig(task="keydoor_incorrect", model=str(paused.parent / "initial.yaml"), steps=STEPS, seed=1,
                    checkpoint_steps=100, overrides=TINY), again, progress=False, stop_at=PAUSE)
    runs = [_copy(paused, tmp_path, "r0"), again]
    for run in runs:
        out = revise(run, spec, progress=False)
        assert out["summary"]["finished"] and out["summary"]["env_steps"] >= STEPS

    def rows(run):
        with (run / "metrics.csv").open(newline="") as fh:
            return [{k: v for k, v in r.items() if k != "wall_time"} for r in csv.DictReader(fh)]

    assert rows(runs[0]) == rows(runs[1])
    paused_rows = rows(paused)
    assert rows(runs[0])[:len(paused_rows)] == paused_rows and len(rows(runs[0])) > len(paused_rows)
    history = read_csv_rows(runs[0] / "critic_history.csv")
    assert history[-1]["corner_nw"] == "" and history[0]["corner_nw"] != ""     # dropped columns end empty
    table = yaml.safe_load((runs[0] / "subgoals.json").read_text())
    assert list(table["marginals"]) == FIVE
    assert (runs[0] / "learning_curve.png").stat().st_size > 0


def test_a_run_without_a_critic_is_refused(tmp_path):
    run = tmp_path / "hdqn"
    train(RunConfig(task="keydoor", agent="hdqn", steps=300, seed=0, overrides=TINY), run, progress=False)
    with pytest.raises(RunError, match="agent 'hdqn' has no sub-goal critic to revise"):
        apply_revision(run, "keydoor-specific", steps=600)
    assert not (run / "revisions").exists()


def test_a_critic_that_never_updated_starts_the_revised_spec_afresh_so_a_re_signed_edge_takes_its_new_sign(tmp_path):
    # the outcome likelihood learns from successes only: paused after one episode, the critic has not updated
    spec = _spec(tmp_path / "first.yaml", "first", FIVE, EDGES, likelihood={"name": "outcome"})
    run = tmp_path / "run"
    train(RunConfig(task="keydoor_incorrect", model=str(spec), steps=STEPS, seed=1, overrides=TINY), run,
          progress=False, stop_at=1)
    critic = load_checkpoint(run / "checkpoint.pt")["agent"]["filter"]["critic"]
    assert critic["num_updates"] == 0
    assert _edges(critic)[frozenset(("yellow_door", "blue_door"))] == -3.0

    resigned = [e if e[:2] != ["yellow_door", "blue_door"] else ["yellow_door", "blue_door", "positive"] for e in EDGES]
    spec2 = tmp_path / "second.yaml"
    spec2.write_text(yaml.safe_dump({**yaml.safe_load(spec.read_text()), "name": "second", "edges": resigned,
                                     "prior": {"name": "ising", "strength": 2.0, "field": -1.0}}))
    record = apply_revision(run, spec2)
    assert record["edges_resigned"] == ["yellow_door--blue_door:negative->positive"]
    assert record["critic_learned"] is False and record["kept"]["theta"] == record["kept"]["couplings"] == 0
    after = load_checkpoint(run / "checkpoint.pt")["agent"]["filter"]["critic"]
    couplings = _edges(after)
    assert couplings[frozenset(("yellow_door", "blue_door"))] == 2.0       # the new prior's strength x the new sign
    assert couplings[frozenset(("yellow_key", "blue_key"))] == -2.0
    assert torch.equal(after["theta"], torch.full((5,), -1.0))              # the new prior's field


def test_the_revise_command_says_whether_the_critics_optimiser_restarts(paused, tmp_path, capsys):
    same = _copy(paused, tmp_path, "same")
    spec = paused.parent / "initial.yaml"
    assert main(["revise", str(same), "--model", str(spec), "--no-train"]) == 0
    out = capsys.readouterr().out
    assert "optimiser is carried over" in out and "optimiser restarts" not in out
    changed = _copy(paused, tmp_path, "changed")
    dropped = _spec(tmp_path / "dropped.yaml", "dropped", FIVE, EDGES)
    assert main(["revise", str(changed), "--model", str(dropped), "--no-train"]) == 0
    assert "optimiser restarts" in capsys.readouterr().out


def test_a_finished_run_revised_without_training_ends_its_critic_history_with_the_revised_g_star(tmp_path):
    # the logs are cut back to the checkpoint, which takes the finished run's last history row with them
    spec = _spec(tmp_path / "initial.yaml", "initial", FIVE + CORNERS, EDGES)
    run = tmp_path / "run"
    train(RunConfig(task="keydoor_incorrect", model=str(spec), steps=400, seed=1, overrides=TINY), run, progress=False)
    end = read_csv_rows(run / "critic_history.csv")[-1]
    assert end["critic"] in ("settled", "final")
    record = apply_revision(run, _spec(tmp_path / "dropped.yaml", "dropped", FIVE, EDGES), train_after=False)
    assert record["finished"]
    history = read_csv_rows(run / "critic_history.csv")
    table = yaml.safe_load((run / "subgoals.json").read_text())
    assert history[-1]["critic"] == end["critic"] and history[-1]["episode"] == end["episode"]
    assert history[-1]["env_steps"] == end["env_steps"]
    assert {n: float(history[-1][n]) for n in FIVE} == {n: round(m, 5) for n, m in table["marginals"].items()}
    assert history[-1]["corner_nw"] == ""                  # a dropped sub-goal has no marginal any more
    assert sum(r["critic"] != "training" for r in history) == 1


def test_a_damaged_checkpoint_is_refused_in_one_line_and_the_run_is_left_as_it_was(paused, tmp_path, capsys):
    from hubsgo_ppl.experiments.io import save_torch

    run = _copy(paused, tmp_path)
    ckpt = load_checkpoint(run / "checkpoint.pt")
    theta = ckpt["agent"]["filter"]["critic"]["theta"]
    ckpt["agent"]["filter"]["critic"]["theta"] = theta[:2]       # fewer factors than the run's sub-goals
    save_torch(run / "checkpoint.pt", ckpt)
    before = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    assert main(["revise", str(run), "--model", str(_spec(tmp_path / "five.yaml", "five", FIVE, EDGES)),
                 "--no-train"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not match its own config" in err[0], err
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == before
    assert not (run / "revisions").exists()


def test_a_finished_run_given_new_sub_goals_is_not_said_to_read_g_star_from_successes_it_no_longer_keeps(tmp_path,
                                                                                                      capsys):
    from hubsgo_ppl.experiments.io import save_torch

    spec = _spec(tmp_path / "five.yaml", "five", FIVE, EDGES)
    run = tmp_path / "run"
    train(RunConfig(task="keydoor_incorrect", model=str(spec), steps=400, seed=1, overrides=TINY), run, progress=False)
    ckpt = load_checkpoint(run / "checkpoint.pt")
    ckpt["agent"]["filter"]["outcomes"] = torch.tensor([[1.0, 1.0, 0.0, 0.0, 1.0]] * 20)   # 20 yellow-route wins
    save_torch(run / "checkpoint.pt", ckpt)
    rows = list(csv.DictReader((run / "metrics.csv").open()))
    with (run / "metrics.csv").open("w", newline="") as fh:                                # and their episodes
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({**r, "success": 1} for r in rows)
    nine = _spec(tmp_path / "nine.yaml", "nine", FIVE + CORNERS, EDGES)
    assert main(["revise", str(run), "--model", str(nine), "--no-train"]) == 0
    out = capsys.readouterr().out
    assert "stays finished" in out and "read from the same recent successes" not in out
    assert "read without recent successes" in out
    assert main(["review", str(run), "--no-gif", "--samples", "200"]) == 0
    out = capsys.readouterr().out
    assert "no successful episode yet" not in out and "none in the filter's window" in out
    assert "the critic has had no outcome evidence" not in (run / "review" / "review.md").read_text()


def test_the_same_spec_again_on_a_finished_run_says_g_star_is_read_as_it_was(tmp_path, capsys):
    spec = _spec(tmp_path / "initial.yaml", "initial", FIVE, EDGES)
    run = tmp_path / "run"
    train(RunConfig(task="keydoor_incorrect", model=str(spec), steps=400, seed=1, overrides=TINY), run, progress=False)
    capsys.readouterr()
    assert apply_revision(run, spec, train_after=False)["finished"]
    err = capsys.readouterr().err
    assert "asks for the critic the run already has; it is recorded as revision 1, and G* is read as it was" in err
    assert "goes on" not in err
