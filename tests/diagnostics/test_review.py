"""`hubsgo review`: G* from the critic, flagged edges, suggested drops, the marginals' trend, refusals."""

import json
import shutil

import numpy as np
import pytest
import yaml
import torch

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments.io import load_checkpoint, save_torch
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.diagnostics.review import (render_markdown, compare_couplings, format_chosen, human_edge_signs, marginal_trend,
                                           negative_edges_against_successes, prior_against_successes, review,
                                           held_up_by_edges, suggested_drops, suggested_links, suggested_spec)
from hubsgo_ppl.experiments.run import RunConfig, RunError, load_run, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]


def _train(out, agent="hubsgo", steps=1500):
    train(RunConfig(task="keydoor", agent=agent, steps=steps, seed=3, overrides=TINY), out, progress=False)
    return out


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("review") / "hubsgo")


def _copy(run, dest):
    shutil.copytree(run, dest)
    shutil.rmtree(dest / "review", ignore_errors=True)
    return dest


def _edit_critic(run_dir, theta=None, coupling=None, outcomes=None):
    """Overwrite entries of the checkpoint's critic parameters ({index: value}) and the filter's
    recent successes (rows of achieved sets)."""
    path = run_dir / "checkpoint.pt"
    ckpt = load_checkpoint(path)
    critic = ckpt["agent"]["filter"]["critic"]
    if outcomes is not None:
        ckpt["agent"]["filter"]["outcomes"] = torch.tensor(outcomes, dtype=torch.float32)
    for i, v in (theta or {}).items():
        critic["theta"][i] = v
    for i, v in (coupling or {}).items():
        critic["coupling"][i] = v
    critic["num_updates"] = max(1, int(critic["num_updates"]))      # these values stand for learned ones
    save_torch(path, ckpt)
    return critic["edges"]


def test_g_star_is_the_critics_top_set_and_files_are_written(run, tmp_path):
    out = tmp_path / "rv"
    r = review(run, out=out, gif=False)
    _, env, agent, _ = load_run(run)
    env.close()
    critic = agent.filter.critic
    ranking = critic.ranking(num_samples=10_000, top_k=5)      # the same critic, freshly loaded
    assert r["g_star"]["subgoals"] == ranking[0]["subgoals"] and r["ranking"] == ranking
    marg = critic.marginals().numpy()
    assert np.allclose([r["marginals"][n] for n in critic.names], marg)
    assert r["env_steps"] == agent.env_steps >= 1500 and r["episodes"] == agent.episodes
    assert r["settled_step"] == agent.settled_step
    assert ("The agent has not settled yet." in (out / "review.md").read_text()) == (agent.settled_step is None)
    assert json.loads((out / "review.json").read_text()) == json.loads(json.dumps(r))
    md = (out / "review.md").read_text()
    assert "G*" in md and f"env step {agent.env_steps:,}" in md and "{" + ", ".join(r["g_star"]["subgoals"]) + "}" in md
    assert (out / "mrf_graph.png").stat().st_size > 0 and not (out / "episode.gif").exists()
    # the spec's edges, unedited, agree with the couplings they initialised
    assert [(c["u"], c["v"], c["human"]) for c in r["couplings"]] == [
        (u, v, {1: "positive", -1: "negative", 0: "unknown"}[s]) for u, v, s in critic.graph.edges]
    assert r["flagged_edges"] == [] and r["trend"]["since"] == "first row of critic_history.csv"
    first = read_csv_rows(run / "critic_history.csv")[0]
    assert r["trend"]["env_steps"] == int(first["env_steps"])
    for n in critic.names:
        assert r["trend"]["delta"][n] == pytest.approx(r["marginals"][n] - float(first[n]))
    # the filter's recent successes and the metrics log
    succ = r["achieved"]["recent_successes"]
    E = agent.filter.outcomes().shape[0]
    assert succ["episodes"] == E
    if E:
        assert succ["frequency"] == pytest.approx(dict(zip(critic.names, agent.filter.outcomes().mean(0).tolist())))
    rows = read_csv_rows(run / "metrics.csv")[-20:]
    assert r["achieved"]["metrics"]["success_rate"] == pytest.approx(np.mean([float(x["success"]) for x in rows]))


def test_flagged_edges_and_drops_from_an_edited_critic(run, tmp_path):
    run2 = _copy(run, tmp_path / "edited")
    wins = [[1, 1, 0, 0, 1], [0, 0, 1, 1, 1], [0, 0, 1, 1, 1], [0, 0, 1, 1, 1]]     # yellow once, blue 3 times
    edges = [tuple(e) for e in _edit_critic(run2, theta={2: -6.0}, coupling={0: -0.8, 2: 0.05, 3: 0.5},
                                            outcomes=wins)]
    # edge 0 is positive and learned -0.8: flagged; edge 2 is negative at +0.05: inside the dead band
    assert edges[0][2] == 1 and edges[2][2] == -1 and edges[3][2] == 1
    r = review(run2, threshold=0.2, gif=False)
    assert [(c["u"], c["v"]) for c in r["flagged_edges"]] == [edges[0][:2]]
    assert r["flagged_edges"][0]["J"] == pytest.approx(-0.8) and r["flagged_edges"][0]["human"] == "positive"
    want = sorted(n for n, p in r["marginals"].items() if p < 0.2)
    assert "blue_key" in want and sorted(d["name"] for d in r["suggested_drops"]) == want
    succ = r["achieved"]["recent_successes"]
    assert succ["episodes"] == 4
    assert succ["frequency"] == pytest.approx({"yellow_key": 0.25, "yellow_door": 0.25, "blue_key": 0.75,
                                               "blue_door": 0.75, "goal": 1.0})
    assert {d["name"]: d["success_frequency"] for d in r["suggested_drops"]}["blue_key"] == 0.75
    md = (run2 / "review" / "review.md").read_text()
    assert f"**edge {edges[0][0]} — {edges[0][1]}**" in md
    assert "**drop blue_key**" in md and "achieved on 75% of the recent successes (the successes need it" in md
    assert ("What the recent successes achieved is read from the 4 the filter keeps. Only 4: a drop read from so few "
            "can remove a route the agent still needs") in md
    more = {**r, "achieved": {**r["achieved"], "recent_successes": {**succ, "episodes": 5}}}
    assert "read from the 5 the filter keeps.\n" in render_markdown(more) and "Only 5" not in render_markdown(more)


def test_second_review_trend_is_the_difference_of_marginals(run, tmp_path):
    run2 = _copy(run, tmp_path / "twice")
    first = review(run2, gif=False)
    _edit_critic(run2, theta={0: 2.0, 4: -3.0})
    second = review(run2, gif=False)
    t = second["trend"]
    assert t["since"] == "previous review" and t["env_steps"] == first["env_steps"]
    assert t["previous"] == first["marginals"]
    for n in second["names"]:
        assert t["delta"][n] == pytest.approx(second["marginals"][n] - first["marginals"][n])
    assert t["delta"]["yellow_key"] > 0.1 and t["delta"]["goal"] < -0.1
    # a third review at the same checkpoint: no change
    third = review(run2, gif=False)
    assert all(abs(d) < 1e-12 for d in third["trend"]["delta"].values())


def test_review_embeds_a_gif_of_a_greedy_episode(run, tmp_path):
    from PIL import Image

    out = tmp_path / "rv"
    r = review(run, out=out)
    assert r["files"]["gif"] == "episode.gif"
    with Image.open(out / "episode.gif") as im:
        assert im.n_frames == r["episode"]["length"] + 1 == r["episode"]["frames"]
    assert "![greedy episode](episode.gif)" in (out / "review.md").read_text()


def test_cli_review_prints_summary(run, tmp_path, capsys, monkeypatch):
    out = tmp_path / "cli"
    assert main(["review", str(run), "--out", str(out), "--no-gif", "--threshold", "0.3"]) == 0
    text = capsys.readouterr().out
    assert "G*: {" in text and "flagged edges" in text and "suggested drops (P(w=1) < 0.30)" in text
    assert "in G*, held by your positive edges, skipped by most successes: " in text
    assert "achieved by every recent success, not in G*: " in text
    assert f"json: {out / 'review.json'}" in text and (out / "review.md").is_file()
    assert "edges you left unknown" not in text         # this run's spec leaves no edge unknown
    # an edge left unknown whose sign the critic learned is named on the terminal too
    import hubsgo_ppl.diagnostics.review as review_mod

    real = review_mod.review
    sign = {"u": "yellow_key", "v": "blue_key", "human": "unknown", "J": -1.25, "learned": "negative",
            "contradicts": False, "suggestion": "make it negative"}
    monkeypatch.setattr(review_mod, "review", lambda *a, **k: {**real(*a, **k), "suggested_signs": [sign]})
    assert main(["review", str(run), "--out", str(out), "--no-gif"]) == 0
    assert ("edges you left unknown, with the sign the critic learned: yellow_key--blue_key negative (J=-1.25)"
            in capsys.readouterr().out)


def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    return err[0]


def test_hdqn_run_is_refused_in_one_line(tmp_path, capsys):
    run = _train(tmp_path / "hdqn", agent="hdqn", steps=300)
    with pytest.raises(RunError, match="no sub-goal critic"):
        review(run)
    assert main(["review", str(run)]) == 2
    assert "agent 'hdqn' has no sub-goal critic" in _one_error_line(capsys)
    assert not (run / "review").exists()


@pytest.mark.parametrize("argv, needle", [
    (["--threshold", "1.5"], "--threshold must be a probability"),
    (["--dead-band", "-1"], "--dead-band must be a number >= 0"),
])
def test_bad_arguments_one_line(run, argv, needle, tmp_path, capsys):
    assert main(["review", str(run), "--out", str(tmp_path / "o"), "--no-gif", *argv]) == 2
    assert needle in _one_error_line(capsys)


def test_missing_run_dir_one_line(capsys):
    assert main(["review", "/nonexistent/run"]) == 2
    assert "no such run directory" in _one_error_line(capsys)


# -- the pieces, on hand-made data ---------------------------------------------------------------

def test_compare_couplings_flags_exactly_the_contradicting_signs():
    pairwise = {("a", "b"): -0.5,     # positive, learned negative: flagged
                ("a", "c"): -0.05,    # positive, inside the dead band: not flagged
                ("b", "c"): 0.3,      # negative, learned positive: flagged
                ("c", "d"): -1.0,     # negative, agrees
                ("a", "d"): 0.7,      # unknown: no flag, a suggested sign
                ("b", "d"): 0.1,      # positive exactly at the band edge: agrees ("near zero")
                ("d", "e"): -0.2}     # not in the spec (a preset's edge): unknown
    spec = {"edges": [["a", "b", "positive"], ["c", "a", "positive"], ["b", "c", "negative"],
                      ["d", "c", "negative"], ["a", "d", "unknown"], ["b", "d", "positive"]]}
    rows = compare_couplings(pairwise, human_edge_signs(spec), dead_band=0.1)
    by = {(r["u"], r["v"]): r for r in rows}
    assert [k for k, r in by.items() if r["contradicts"]] == [("a", "b"), ("b", "c")]
    assert by[("a", "c")]["human"] == "positive" and by[("a", "c")]["learned"] == "near zero"
    assert by[("a", "d")]["suggestion"] == "declare the edge positive" and not by[("a", "d")]["contradicts"]
    assert by[("d", "e")]["human"] == "unknown" and by[("d", "e")]["suggestion"] == "declare the edge negative"
    assert by[("b", "d")]["suggestion"] is None and by[("c", "d")]["suggestion"] is None
    assert by[("a", "b")]["suggestion"] == "flip the edge to negative or remove it"
    # a wider band forgives the weaker contradiction
    wide = compare_couplings(pairwise, human_edge_signs(spec), dead_band=0.4)
    assert [(r["u"], r["v"]) for r in wide if r["contradicts"]] == [("a", "b")]
    # without a spec, the graph's signs are the human's
    assert human_edge_signs(None, [("a", "b", 1), ("b", "c", -1), ("c", "d", 0)]) == {
        frozenset("ab"): "positive", frozenset("bc"): "negative", frozenset("cd"): "unknown"}


def test_metrics_summary_reads_visited_columns_when_logged(tmp_path):
    from hubsgo_ppl.diagnostics.review import metrics_summary

    path = tmp_path / "metrics.csv"
    path.write_text("episode,env_steps,success,return,visited/a,visited/b\n"
                    "0,10,0,0.0,1,0\n1,20,1,0.5,1,0\n2,30,1,0.7,1,1\n3,40,0,0.0,0,1\n")
    m = metrics_summary(path, ["a", "b"], last=3)
    assert m["episodes"] == 3 and m["first_episode"] == 1 and m["successes"] == 2
    assert m["success_rate"] == pytest.approx(2 / 3) and m["mean_return"] == pytest.approx(0.4)
    assert m["frequency"] == {"a": 1.0, "b": 0.5}                # over the successful episodes only
    assert metrics_summary(tmp_path / "none.csv", ["a"]) is None


def test_drops_and_trend_on_hand_made_marginals():
    marg = {"a": 0.05, "b": 0.5, "c": 0.19, "d": 0.2}
    drops = suggested_drops(marg, 0.2, {"a": 0.0, "b": 1.0, "c": 1.0, "d": 1.0})
    assert [d["name"] for d in drops] == ["a", "c"] and drops[1]["success_frequency"] == 1.0
    assert suggested_drops(marg, 0.2)[0]["success_frequency"] is None
    t = marginal_trend(marg, {"source": "previous review", "env_steps": 10, "marginals": {"a": 0.1, "b": 0.5,
                                                                                         "c": 0.0, "d": 1.0}})
    assert t["delta"] == pytest.approx({"a": -0.05, "b": 0.0, "c": 0.19, "d": -0.8})
    assert marginal_trend(marg, None)["delta"] is None
    assert format_chosen(["a", "a", "b", "a"]) == "a x2, b, a"
    # a long failed episode: the first runs, then how many options are left
    assert format_chosen(["a", "b"] * 20 + ["c", "c"], limit=3) == "a, b, a, ... (39 more)"
    assert format_chosen(["a", "a", "b"], limit=2) == "a x2, b"


def test_prior_against_successes_names_what_the_edges_hold_in_and_what_the_successes_need():
    human = {frozenset(("key", "door")): "positive", frozenset(("corner", "goal")): "positive",
             frozenset(("corner", "key")): "negative", frozenset(("door", "other")): "unknown"}
    names = ["key", "door", "goal", "corner", "other"]
    freq = {"key": 1.0, "door": 1.0, "goal": 1.0, "corner": 0.3, "other": 0.5}
    r = prior_against_successes(["key", "door", "corner"], names, freq, human)
    assert r["held_by_edges"] == [{"name": "corner", "success_frequency": 0.3, "positive_edges": ["goal"]}]
    assert r["needed_not_in_g_star"] == [{"name": "goal", "success_frequency": 1.0, "positive_edges": ["corner"]}]
    # at half of the successes a sub-goal is not flagged; nor is one in no success and not in G*
    assert prior_against_successes(["key", "door", "goal", "other"], names, freq, human) == {
        "held_by_edges": [], "needed_not_in_g_star": []}
    assert prior_against_successes([], names, None, human) == {"held_by_edges": [], "needed_not_in_g_star": []}


def test_held_up_by_edges_names_what_positive_edges_keep_above_the_drop_threshold_outside_g_star():
    human = {frozenset(("corner", "goal")): "positive", frozenset(("key", "door")): "positive",
             frozenset(("other", "goal")): "unknown"}
    marg = {"key": 0.9, "door": 0.95, "goal": 0.99, "corner": 0.36, "low": 0.1, "other": 0.4}
    freq = {"key": 1.0, "door": 1.0, "goal": 1.0, "corner": 0.05, "low": 0.0, "other": 0.0}
    assert held_up_by_edges(["key", "door", "goal"], marg, freq, human, threshold=0.2) == [
        {"name": "corner", "marginal": 0.36, "success_frequency": 0.05, "positive_edges": ["goal"]}]
    # in G* it is held_by_edges' to name; below the threshold a drop is suggested; half of the successes
    # is enough; an unknown edge holds nothing up; no successes, nothing to compare
    assert held_up_by_edges(["key", "door", "goal", "corner"], marg, freq, human, 0.2) == []
    assert held_up_by_edges(["key", "door", "goal"], marg, freq, human, 0.4) == []
    assert held_up_by_edges(["key", "door", "goal"], marg, {**freq, "corner": 0.5}, human, 0.2) == []
    assert held_up_by_edges([], marg, None, human, 0.2) == []


def test_negative_edges_whose_ends_every_success_achieves_are_named():
    names = ["a", "b", "c", "d"]
    human = {frozenset(("a", "b")): "negative", frozenset(("c", "b")): "negative", frozenset(("a", "d")): "negative",
             frozenset(("b", "d")): "positive", frozenset(("c", "d")): "unknown", frozenset(("a", "zz")): "negative"}
    wins = np.array([[1, 1, 1, 1], [1, 1, 0, 1], [1, 0, 1, 1], [0, 1, 0, 1]])
    # a and d: 3 of 4 successes, a and b: 2 of 4, b and c: 1 of 4: by default only an edge whose two ends
    # every success achieved is named, and none is here; the positive and unknown edges are never named,
    # however often both ends hold; an edge to a sub-goal not in the run is ignored
    assert negative_edges_against_successes(wins, names, human) == []
    assert negative_edges_against_successes(wins, names, human, share=0.75) == [
        {"u": "a", "v": "d", "both_frequency": 0.75}]
    assert negative_edges_against_successes(wins, names, human, share=0.5) == [
        {"u": "a", "v": "b", "both_frequency": 0.5}, {"u": "a", "v": "d", "both_frequency": 0.75}]
    assert negative_edges_against_successes(torch.tensor(wins[:1], dtype=torch.float32), names, human) == [
        {"u": "a", "v": "b", "both_frequency": 1.0}, {"u": "a", "v": "d", "both_frequency": 1.0},
        {"u": "b", "v": "c", "both_frequency": 1.0}]
    assert negative_edges_against_successes(np.zeros((0, 4)), names, human) == []


def test_review_names_a_negative_edge_between_two_subgoals_the_successes_both_achieve(run, tmp_path, capsys):
    run2 = _copy(run, tmp_path / "together")
    _edit_critic(run2)
    names = list(load_run(run2)[2].filter.critic.names)
    # the spec says the keys exclude each other (yellow_key -- blue_key negative), and all 4 recent
    # successes held both keys at some step
    wins = [[1 if n in ("yellow_key", "blue_key", "yellow_door", "goal") else 0 for n in names] for k in range(4)]
    _edit_critic(run2, outcomes=wins)
    r = review(run2, threshold=0.2, gif=False)
    assert r["negative_edges_achieved_together"] == [
        {"u": min(("yellow_key", "blue_key"), key=names.index), "v": max(("yellow_key", "blue_key"), key=names.index),
         "both_frequency": 1.0}]
    md = (run2 / "review" / "review.md").read_text()
    c = r["negative_edges_achieved_together"][0]
    assert (f"**edge {c['u']} — {c['v']}**: you said *negative* (one excludes the other), yet 100% of the recent "
            "successes achieved both; remove it, or make it positive if the route needs both") in md
    assert f"| {c['u']} — {c['v']} | negative |" in md and "**the successes achieve both**" in md
    assert main(["review", str(run2), "--no-gif", "--out", str(tmp_path / "cli")]) == 0
    assert f"both ends achieved by every recent success: {c['u']}--{c['v']} (100%)" in capsys.readouterr().out
    # the suggested spec leaves that edge out, and a revision takes it as it is
    import yaml

    from hubsgo_ppl.experiments.revise import revise

    path = run2 / "review" / "suggested_spec.yaml"
    suggested = yaml.safe_load(path.read_text())
    assert r["files"]["suggested_spec"] == "suggested_spec.yaml" and suggested["name"].endswith("-reviewed")
    assert not any({u, v} == {"yellow_key", "blue_key"} for u, v, _ in suggested["edges"])
    assert f"hubsgo revise {run2} --model {path}" in md
    record = revise(run2, path, steps=2000, train_after=False)["revision"]
    assert {"yellow_key--blue_key", "blue_key--yellow_key"} & set(record["edges_dropped"])
    # three successes of four holding both keys: nothing is named
    _edit_critic(run2, outcomes=[[1 if n in ("yellow_key", "yellow_door", "goal") or (n == "blue_key" and k < 3)
                                  else 0 for n in names] for k in range(4)])
    assert review(run2, threshold=0.2, gif=False)["negative_edges_achieved_together"] == []


def test_the_suggested_spec_applies_the_reviews_changes_and_adds_nothing():
    spec = {"name": "toy", "task": "keydoor", "graph": "specific", "prior": {"name": "ising"},
            "subgoals": ["key", "door", "goal", "corner", "other", "ball"],
            "edges": [["key", "door", "positive"], ["door", "goal", "negative"], ["corner", "goal", "positive"],
                      ["key", "ball", "negative"], ["other", "key", "unknown"], ["ball", "goal", "unknown"]]}
    r = {"critic_updates": 3,
         "suggested_drops": [{"name": "other", "success_frequency": 0.1}, {"name": "ball", "success_frequency": 0.6},
                             {"name": "goal", "success_frequency": None}],
         "flagged_edges": [{"u": "door", "v": "goal", "learned": "positive"}],
         "suggested_signs": [{"u": "ball", "v": "goal", "learned": "negative"},
                             {"u": "corner", "v": "door", "learned": "negative"}],
         "negative_edges_achieved_together": [{"u": "key", "v": "ball", "both_frequency": 0.7}],
         "held_by_edges": [{"name": "corner", "success_frequency": 0.2, "positive_edges": ["goal"]}],
         "needed_not_in_g_star": [{"name": "key", "success_frequency": 1.0, "positive_edges": []}]}
    new = suggested_spec(r, spec)
    # "other" goes (10% of the successes), "ball" stays (60%: the successes need it), and so does the goal
    # (no successes were counted for it); its flagged edge takes the learned sign, the unknown edge its
    # suggested sign, the graph preset's edge is added, and the edges the successes contradict go
    assert new["name"] == "toy-reviewed" and new["subgoals"] == ["key", "door", "goal", "corner", "ball"]
    assert new["edges"] == [["key", "door", "positive"], ["door", "goal", "positive"], ["ball", "goal", "negative"],
                            ["corner", "door", "negative"]]
    assert {k: new[k] for k in ("task", "graph", "prior")} == {k: spec[k] for k in ("task", "graph", "prior")}
    # before the critic's first update the marginals are the prior's: nothing is dropped
    assert suggested_spec({**r, "critic_updates": 0}, spec)["subgoals"] == spec["subgoals"]
    # no suggestions: the spec as it was, renamed
    assert suggested_spec({}, spec) == {**spec, "name": "toy-reviewed"}
    # a spec written without a task names the run's; no key is written as null
    bare = {**spec, "task": None, "likelihood": None}
    assert suggested_spec({"task": "moat"}, bare) == {k: v for k, v in {**spec, "name": "toy-reviewed",
                                                                         "task": "moat"}.items()}
    assert "task" not in suggested_spec({}, bare)


def test_review_says_which_edge_holds_a_subgoal_the_successes_skip(run, tmp_path):
    run2 = _copy(run, tmp_path / "held")
    edges = [tuple(e) for e in _edit_critic(run2)]
    names = list(load_run(run2)[2].filter.critic.names)
    # q all but certain of {yellow_key, yellow_door, goal}; the successes took the yellow route and
    # reached the goal, but only one of four held the yellow key at any step
    theta = {i: (6.0 if n in ("yellow_key", "yellow_door", "goal") else -6.0) for i, n in enumerate(names)}
    wins = [[1 if n in ("yellow_door", "goal") or (k == 0 and n == "yellow_key") else 0 for n in names]
            for k in range(4)]
    _edit_critic(run2, theta=theta, coupling={j: 0.0 for j in range(len(edges))}, outcomes=wins)
    r = review(run2, threshold=0.2, gif=False)
    assert set(r["g_star"]["subgoals"]) == {"yellow_key", "yellow_door", "goal"}
    assert r["held_by_edges"] == [{"name": "yellow_key", "success_frequency": 0.25,
                                   "positive_edges": ["yellow_door"]}]
    assert r["needed_not_in_g_star"] == []
    md = (run2 / "review" / "review.md").read_text()
    assert ("**yellow_key is in G* but only 25% of the recent successes achieved it**: your positive edges hold it "
            "there (yellow_key — yellow_door)") in md


def test_drops_before_the_critics_first_update_are_called_its_starting_values(run, tmp_path, capsys):
    """Before any evidence the marginals are the spec's prior: a drop suggested then is the human's own
    knowledge read back, and the review says so; once the critic has updated it does not."""
    r = review(run, out=tmp_path / "rv0", gif=False, threshold=0.5)     # no success in its 1,500 steps
    assert r["critic_updates"] == 0 and r["suggested_drops"]
    md0 = (tmp_path / "rv0" / "review.md").read_text()
    assert "the critic has not updated on this run yet: this is its starting value (your spec's prior" in md0
    # the suggested spec keeps every sub-goal, and review.md says so rather than "these changes applied" alone
    kept = yaml.safe_load((tmp_path / "rv0" / "suggested_spec.yaml").read_text())["subgoals"]
    assert {d["name"] for d in r["suggested_drops"]} <= set(kept)
    assert "no sub-goal dropped and no edge removed for what G* holds: the critic's starting values are your" in md0
    assert main(["review", str(run), "--out", str(tmp_path / "cli0"), "--no-gif", "--threshold", "0.5"]) == 0
    assert "(the critic has not updated on this run yet: its starting values, not what this run learned)" in capsys.readouterr().out
    r = review(run, out=tmp_path / "rv_none", gif=False, threshold=0.0)        # nothing to suggest, and no evidence
    md = (tmp_path / "rv_none" / "review.md").read_text()
    assert not r["suggested_drops"] and "None yet: the critic has not updated on this run" in md
    assert "every learned coupling agrees" not in md
    learned = _copy(run, tmp_path / "learned")
    _edit_critic(learned, theta={2: -6.0}, outcomes=[[1, 1, 0, 0, 1]])
    r = review(learned, out=tmp_path / "rv1", gif=False, threshold=0.5)
    assert r["critic_updates"] == 1 and r["suggested_drops"]
    assert "has not updated" not in (tmp_path / "rv1" / "review.md").read_text()
    assert main(["review", str(learned), "--out", str(tmp_path / "cli1"), "--no-gif", "--threshold", "0.5"]) == 0
    assert "has not updated" not in capsys.readouterr().out


def test_suggested_links_tie_to_a_goal_that_g_star_leaves_out_what_most_successes_achieved():
    names = ["key", "door", "other", "cell", "goal"]
    freq = {"key": 1.0, "door": 0.5, "other": 0.45, "cell": 1.0, "goal": 1.0}
    human = {frozenset(("door", "goal")): "unknown"}
    assert suggested_links([], names, freq, ["goal"], human) == [
        {"u": "key", "v": "goal", "human": None, "success_frequency": 1.0},
        {"u": "door", "v": "goal", "human": "unknown", "success_frequency": 0.5},
        {"u": "cell", "v": "goal", "human": None, "success_frequency": 1.0}]
    # a positive edge the human already gave is not suggested again; a sub-goal in G* is linked too
    assert [c["u"] for c in suggested_links(["key"], names, freq, ["goal"], {frozenset(("cell", "goal")): "positive"})
            ] == ["key", "door"]
    # G* holds the goal: a sub-goal the successes pass but the human left unlinked (the cell) stays out
    assert suggested_links(["key", "goal"], names, freq, ["goal"], {}) == []
    # a goal that not every success reached, a task without a goal sub-goal, or no success yet
    assert suggested_links([], names, {**freq, "goal": 0.95}, ["goal"], {}) == []
    assert suggested_links([], names, freq, [], {}) == [] and suggested_links([], names, None, ["goal"], {}) == []


def test_the_suggested_spec_unlinks_what_positive_edges_hold_up_outside_g_star():
    spec = {"name": "toy", "task": "keydoor_incorrect", "graph": "specific", "subgoals": ["key", "door", "goal", "corner"],
            "edges": [["key", "door", "positive"], ["door", "goal", "positive"], ["corner", "goal", "positive"]]}
    r = {"critic_updates": 4, "held_up_by_edges": [{"name": "corner", "marginal": 0.4, "success_frequency": 0.0,
                                                    "positive_edges": ["goal"]}]}
    new = suggested_spec(r, spec)
    assert new["subgoals"] == spec["subgoals"] and new["edges"] == spec["edges"][:2]
    # before the critic's first update G* is the prior's, which the edges shape: they stay
    assert suggested_spec({**r, "critic_updates": 0}, spec)["edges"] == spec["edges"]


def test_the_suggested_spec_links_the_route_when_g_star_leaves_out_the_goal():
    spec = {"name": "toy", "task": "keydoor", "graph": "independent", "prior": {"name": "ising"},
            "subgoals": ["key", "door", "other", "goal"], "edges": [["key", "other", "negative"]]}
    links = [{"u": "key", "v": "goal", "human": None}, {"u": "door", "v": "goal", "human": None}]
    r = {"critic_updates": 5, "suggested_drops": [{"name": "other", "success_frequency": 0.0}],
         "suggested_links": links}
    new = suggested_spec(r, spec)
    # the independent preset would ignore edges, so the graph becomes specific, with the links as its
    # only edges: the edge the spec listed acted on nothing under that preset
    assert new["graph"] == "specific" and new["subgoals"] == ["key", "door", "goal"]
    assert new["edges"] == [["key", "goal", "positive"], ["door", "goal", "positive"]]
    # on a fully connected graph a listed unknown pair takes the positive sign, once
    full = {**spec, "graph": "fully_connected", "edges": [["door", "goal", "unknown"], ["key", "other", "negative"]]}
    new = suggested_spec({**r, "suggested_drops": [], "suggested_links": [{**links[0]}, {**links[1], "human": "unknown"}]},
                         full)
    assert new["graph"] == "fully_connected"
    assert new["edges"] == [["key", "other", "negative"], ["key", "goal", "positive"], ["door", "goal", "positive"]]


def test_the_suggested_links_move_the_exact_posterior_mode_from_the_empty_set_to_the_route():
    """Enumeration of all 2^5 sets: under the shipped Ising prior (strength 3, field -2) without edges,
    successes that all took {blue_key, blue_door, goal}, read at the outcome likelihood's settled power,
    leave the posterior's mode empty (1.56 nats of evidence per sub-goal against a field of 2); with the
    review's two links to the goal the mode is that route, by a margin of at least 1 nat."""
    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.infer.likelihoods import OutcomeLikelihood
    from hubsgo_ppl.infer.priors import IsingPrior

    names = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]
    route = torch.tensor([0.0, 0.0, 1.0, 1.0, 1.0])
    lik = OutcomeLikelihood()
    states = torch.tensor([[(k >> i) & 1 for i in range(5)] for k in range(32)], dtype=torch.float32)
    evidence = lik.log_likelihood(states, route.expand(20, 5)) * lik.settled_scale()

    def posterior(edges):
        prior = IsingPrior(SubgoalGraph(names, edges), strength=3.0, field=-2.0)
        logp = prior.distribution().log_prob(states) + evidence
        return logp - torch.logsumexp(logp, 0)

    before = posterior([])
    assert torch.equal(states[before.argmax()], torch.zeros(5))
    after = posterior([("blue_key", "goal", 1), ("blue_door", "goal", 1)])
    top2 = after.topk(2)
    assert torch.equal(states[top2.indices[0]], route)
    assert float(top2.values[0] - top2.values[1]) > 1.0
    # the route's marginals under the suggestion, exact: each sub-goal of the route above 0.8
    marg = (after.exp().unsqueeze(-1) * states).sum(0)
    assert (marg[2:] > 0.8).all() and (marg[:2] < 0.2).all(), marg


def test_links_for_successes_split_evenly_between_two_routes_leave_one_route_as_the_exact_mode():
    """Ten successes by each of two routes: every route sub-goal reaches half of them, so the review links
    all four to the goal. Enumerating all 2^5 sets at the settled power, the posterior's two modes are
    the two routes, tied, and their union is below either: G* names one route, not both."""
    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.infer.likelihoods import OutcomeLikelihood
    from hubsgo_ppl.infer.priors import IsingPrior

    names = ["a_key", "a_door", "b_key", "b_door", "goal"]
    a, b = torch.tensor([1.0, 1, 0, 0, 1]), torch.tensor([0.0, 0, 1, 1, 1])
    freq = {"a_key": 0.5, "a_door": 0.5, "b_key": 0.5, "b_door": 0.5, "goal": 1.0}
    links = suggested_links([], names, freq, ["goal"], {})
    assert [c["u"] for c in links] == names[:4]
    lik = OutcomeLikelihood()
    states = torch.tensor([[(k >> i) & 1 for i in range(5)] for k in range(32)], dtype=torch.float32)
    edges = [(c["u"], c["v"], 1) for c in links]
    logp = IsingPrior(SubgoalGraph(names, edges), strength=3.0, field=-2.0).distribution().log_prob(states)
    logp = logp + lik.log_likelihood(states, torch.stack([a] * 10 + [b] * 10)) * lik.settled_scale()
    p = (logp - torch.logsumexp(logp, 0)).exp()
    index = {tuple(s.int().tolist()): i for i, s in enumerate(states)}
    pa, pb, union = (float(p[index[tuple(x)]]) for x in ([1, 1, 0, 0, 1], [0, 0, 1, 1, 1], [1, 1, 1, 1, 1]))
    assert abs(pa - pb) < 1e-6 and pa == pytest.approx(float(p.max()))
    assert union < pa / 2, (pa, union)        # 0.081 against 0.188


def test_review_and_revise_of_a_finished_run_without_edges_name_the_route(tmp_path, capsys):
    """A finished run whose critic has no edges: G* is empty though every success took the blue route.
    The review suggests linking the route to the goal; `hubsgo revise --no-train` keeps the run finished
    and rewrites subgoals.json with the revised critic's G*, read from the same successes."""
    run = tmp_path / "independent"
    train(RunConfig(task="keydoor", agent="hubsgo", graph="independent", steps=400, seed=3, overrides=TINY), run,
          progress=False)
    names = list(load_run(run)[2].filter.critic.names)
    blue = [[1 if n in ("blue_key", "blue_door", "goal") else 0 for n in names]] * 20
    _edit_critic(run, theta={i: -2.0 for i in range(len(names))}, outcomes=blue)
    ckpt = load_checkpoint(run / "checkpoint.pt")
    ckpt["agent"]["settled_step"] = int(ckpt["env_steps"])        # read G* as a settled agent's
    save_torch(run / "checkpoint.pt", ckpt)
    r = review(run, gif=False)
    assert r["g_star"]["subgoals"] == [] and r["goals"] == ["goal"]
    assert [(c["u"], c["v"]) for c in r["suggested_links"]] == [("blue_key", "goal"), ("blue_door", "goal")]
    md = (run / "review" / "review.md").read_text()
    assert "**link blue_key — goal (positive)**: G* leaves out goal, which every recent success reached" in md
    assert "suggested_spec.yaml --no-train`" in md       # the run has taken its budget
    spec = run / "review" / "suggested_spec.yaml"
    assert main(["revise", str(run), "--model", str(spec), "--no-train"]) == 0
    out = capsys.readouterr().out
    assert "stays finished" in out
    g_star = json.loads((run / "subgoals.json").read_text())["ranking"][0]
    assert g_star["subgoals"] == ["blue_key", "blue_door", "goal"] and g_star["prob"] > 0.5, g_star
    assert load_checkpoint(run / "checkpoint.pt")["env_steps"] == ckpt["env_steps"]
    # training on needs a budget above the steps taken, as before
    assert main(["revise", str(run), "--model", str(spec), "--no-progress"]) == 2
    assert "pass --steps TOTAL above" in capsys.readouterr().err
