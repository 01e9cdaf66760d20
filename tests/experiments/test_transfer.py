"""`hubsgo train NEW_TASK --init-from RUN [--transfer critic,high,low]`: a run starts from another run's
critic, high level and low level, sub-goals matched by name; observations of another shape are refused."""

import pytest
import torch
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.experiments.io import load_checkpoint
from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, RunError, train

TINY = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=64", "low.batch_size=32",
        "low.hidden=[32]", "high.hidden=[32]", "env.max_steps=150", "loop.option_steps=15"]
CLI_TINY = [a for item in TINY for a in ("--set", item)]


#: the pairs whose grids differ in size observe egocentrically (the symbolic observation's shape is the grid's)
EGO = {"annex": ["env.obs_mode=egocentric"], "gallery": ["env.obs_mode=egocentric"], "moat": ["env.obs_mode=egocentric"]}


def _source(root, task, seed=0):
    # a TD likelihood, so that the source critic has learned something in a tiny budget
    from hubsgo_ppl.specs import load_model_spec

    out = root / f"{task}-src"
    spec = load_model_spec(f"{task}-specific").model_dump(mode="json")
    spec["likelihood"] = {"name": "gaussian"}
    path = root / f"{task}-td.yaml"
    path.write_text(yaml.safe_dump(spec))
    train(RunConfig(task=task, model=str(path), steps=900, seed=seed, overrides=TINY + EGO.get(task, [])), out,
          progress=False)
    return out


@pytest.fixture(scope="module")
def sources(tmp_path_factory):
    root = tmp_path_factory.mktemp("transfer")
    return {task: _source(root, task) for task in ("keydoor", "fourroom", "threepair", "vault", "annex", "gallery", "moat")}


@pytest.mark.parametrize("source, target", [("keydoor", "keydoor_moved"), ("fourroom", "fourroom_moved"),
                                            ("threepair", "threepair_moved"), ("vault", "vault_moved"),
                                            ("annex", "annex_wide"), ("gallery", "gallery_turned"),
                                            ("moat", "moat_mirror")])
def test_tiny_transfer_to_the_similar_task(sources, tmp_path, source, target, capsys):
    src = load_checkpoint(sources[source] / "checkpoint.pt")["agent"]
    assert src["filter"]["critic"]["num_updates"] > 0
    out = tmp_path / target
    cfg = RunConfig(task=target, steps=600, seed=2, overrides=TINY + EGO.get(source, []), init_from=str(sources[source]))
    train(cfg, out, progress=False, max_episodes=0)          # the run's state before its first episode
    # between two layouts, an observation of absolute cells gets a note; the egocentric one does not
    noted = "which names absolute cells, so networks trained on" in capsys.readouterr().err
    assert noted == (source not in EGO)
    start = load_checkpoint(out / "checkpoint.pt")
    agent = start["agent"]
    critic, scritic = agent["filter"]["critic"], src["filter"]["critic"]
    assert critic["names"] == scritic["names"]                # the same sub-goal names, the same order
    assert torch.equal(critic["theta"], scritic["theta"])
    # edges by unordered name pair: fourroom_moved's spec joins other doorways than fourroom's
    src_j = {frozenset((u, v)): j for (u, v, _), j in zip(scritic["edges"], scritic["coupling"])}
    shared = 0
    for (u, v, sign), j in zip(critic["edges"], critic["coupling"]):
        if frozenset((u, v)) in src_j:
            assert torch.equal(j, src_j[frozenset((u, v))]), (u, v)
            shared += 1
        else:                                   # a new edge: the ising prior's strength * sign (init: prior)
            assert float(j) == 3.0 * sign, (u, v)
    assert shared >= 4
    assert critic["num_updates"] == 0 and critic["optimizer"]["state"] == {}
    for part in ("high", "low"):
        for net in ("q", "q_target"):
            for k, v in src[part][net].items():
                assert torch.equal(agent[part][net][k], v), (part, net, k)
        assert agent[part]["buffer"]["size"] == 0 and agent[part]["opt"]["state"] == {}
    assert agent["filter"]["mask"] is not None, "Ĝt comes from the transferred critic from the first episode on"
    assert start["env_steps"] == 0 and start["episodes"] == 0
    init = yaml.safe_load((out / "config.yaml").read_text())["init_from"]
    assert init["task"] == source and init["parts"] == ["critic", "high", "low"]
    n = len(critic["names"])
    assert init["mapped"]["high"]["outputs"] == f"{n}/{n}"
    assert init["mapped"]["critic"]["edges"] == f"{shared}/{len(critic['edges'])}"

    summary = train(cfg, out, resume=True, progress=False)   # and it trains on from there
    assert summary["finished"] and summary["env_steps"] >= 600
    assert [int(r["episode"]) for r in read_csv_rows(out / "metrics.csv")] == list(range(summary["episodes"]))


def test_observations_of_another_shape_are_refused_in_one_line(sources, tmp_path, capsys):
    out = tmp_path / "twowall"
    assert main(["train", "twowall", "--init-from", str(sources["keydoor"]), "--out", str(out), "--steps", "300",
                 "--no-progress", *CLI_TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    assert "observation shapes differ: keydoor has (35,), twowall has (41,)" in err[0]
    assert err[0].endswith("or observe egocentrically in both runs (--set env.obs_mode=egocentric: its shape "
                           "depends on the sub-goal catalogue only, not on the grid)"), err[0]
    assert not out.exists(), "a refused transfer writes nothing"
    # an h-DQN run has no critic: the way out is no --init-from, not the critic alone
    assert main(["train", "twowall", "--agent", "hdqn", "--init-from", str(sources["keydoor"]), "--out", str(out),
                 "--steps", "300", "--no-progress", *CLI_TINY]) == 2
    err = capsys.readouterr().err
    assert "same observation shape; train without --init-from (no critic to transfer: the runs are hubsgo and hdqn)" \
        in err and "--transfer critic" not in err, err
    for argv, needle in ((["--transfer", "brain"], "--transfer brain: use some of critic, high, low"),
                         (["--agent", "hdqn", "--transfer", "critic"], "cannot transfer the critic")):
        assert main(["train", "keydoor_moved", "--init-from", str(sources["keydoor"]), "--out", str(out),
                     "--no-progress", *argv]) == 2
        assert needle in capsys.readouterr().err
    with pytest.raises(RunError, match="no such run directory"):
        train(RunConfig(task="keydoor", init_from=str(tmp_path / "nope")), tmp_path / "o", progress=False)


def test_the_critic_alone_transfers_by_name_to_a_larger_catalogue(sources, tmp_path):
    out = tmp_path / "twowall"
    train(RunConfig(task="twowall", steps=300, seed=0, overrides=TINY, init_from=str(sources["keydoor"]),
                    transfer=["critic"]), out, progress=False, max_episodes=0)
    critic = load_checkpoint(out / "checkpoint.pt")["agent"]["filter"]["critic"]
    src = load_checkpoint(sources["keydoor"] / "checkpoint.pt")["agent"]["filter"]["critic"]
    for j, name in enumerate(critic["names"]):
        if name in src["names"]:
            assert torch.equal(critic["theta"][j], src["theta"][src["names"].index(name)]), name
        else:                                   # a sub-goal keydoor lacks: the ising prior's field
            assert float(critic["theta"][j]) == -2.0, name
    assert yaml.safe_load((out / "config.yaml").read_text())["init_from"]["mapped"]["critic"]["subgoals"] == "5/9"


def _loop(run):
    """The run's loop settings, its config's over LoopConfig's defaults."""
    from hubsgo_ppl.agents.loop import LoopConfig

    return {**LoopConfig().model_dump(), **yaml.safe_load((run / "config.yaml").read_text())["hyper"]["loop"]}


def test_transferred_parts_pick_up_their_schedules_where_the_source_left_them(tmp_path):
    from hubsgo_ppl.agents.schedules import LinearSchedule

    src = tmp_path / "src"      # paused a tenth of the way through its budget: every ε mid-decay
    train(RunConfig(task="keydoor", steps=3000, seed=0, overrides=TINY), src, progress=False, stop_at=300)
    at = load_checkpoint(src / "checkpoint.pt")["env_steps"] / 3000
    s = _loop(src)

    def left(key):              # the source schedule's value at its last step
        return round(LinearSchedule(s[f"{key}_start"], s[f"{key}_end"], s[f"{key}_fraction"])(at), 6)

    want = {"filter_start": left("filter"), "explore_start": left("explore"), "low_explore_start": left("low_explore")}
    assert 0.5 < want["filter_start"] < 0.9 and 0.05 < want["explore_start"] < 1.0
    runs = {"all": RunConfig(task="keydoor_moved", overrides=TINY, init_from=str(src)),
            "low": RunConfig(task="keydoor_moved", overrides=TINY, init_from=str(src), transfer=["low"]),
            "set": RunConfig(task="keydoor_moved", overrides=[*TINY, "loop.explore_start=0.7"], init_from=str(src)),
            "restart": RunConfig(task="keydoor_moved", overrides=TINY, init_from=str(src), restart_schedules=True),
            "scratch": RunConfig(task="keydoor_moved", overrides=TINY)}
    for name, cfg in runs.items():
        train(cfg, tmp_path / name, progress=False, max_episodes=0)
    fresh = _loop(tmp_path / "scratch")
    starts = {name: {k: _loop(tmp_path / name)[k] for k in want} for name in runs}
    assert starts["all"] == want
    assert yaml.safe_load((tmp_path / "all" / "config.yaml").read_text())["init_from"]["schedules"] == want
    assert starts["low"] == {**{k: fresh[k] for k in want}, "low_explore_start": want["low_explore_start"]}
    assert starts["set"] == {**want, "explore_start": 0.7}          # what the user sets wins
    assert starts["restart"] == {k: fresh[k] for k in want}
    assert fresh["explore_start"] == 1.0 and fresh["filter_start"] == 0.5


def test_a_transfer_changes_no_loop_setting_but_the_schedules_it_continues(tmp_path):
    src = tmp_path / "src"
    train(RunConfig(task="keydoor", steps=3000, seed=0, overrides=TINY), src, progress=False, stop_at=300)
    runs = {"all": RunConfig(task="keydoor_moved", overrides=TINY, init_from=str(src)),
            "scratch": RunConfig(task="keydoor_moved", overrides=TINY)}
    for name, cfg in runs.items():
        train(cfg, tmp_path / name, progress=False, max_episodes=0)
    moved, scratch = _loop(tmp_path / "all"), _loop(tmp_path / "scratch")
    starts = {"filter_start", "explore_start", "low_explore_start"}
    assert {k for k in moved if moved[k] != scratch.get(k)} <= starts
    assert {k: v for k, v in moved.items() if k not in starts} == {k: v for k, v in scratch.items() if k not in starts}
    assert "defaults" not in yaml.safe_load((tmp_path / "all" / "config.yaml").read_text())["init_from"]


def test_a_transferred_critic_completes_what_the_agent_holds_and_keeps_doing_so_after_resume(tmp_path):
    """The transferred critic's Ĝt falls back to q's completion of the achieved set (not the mode of a
    route the agent can no longer take); a run from scratch keeps the mode; a checkpoint keeps it."""
    from hubsgo_ppl.experiments.run import load_run

    src = tmp_path / "src"
    train(RunConfig(task="keydoor", steps=3000, seed=0, overrides=TINY), src, progress=False, stop_at=300)
    train(RunConfig(task="keydoor_moved", overrides=TINY, init_from=str(src), steps=3000), tmp_path / "moved",
          progress=False, stop_at=300)
    train(RunConfig(task="keydoor_moved", overrides=TINY, steps=3000), tmp_path / "scratch", progress=False,
          stop_at=300)
    assert load_run(tmp_path / "moved")[2].filter.complete_missing is True
    assert load_run(tmp_path / "scratch")[2].filter.complete_missing is False


def test_grids_of_another_size_with_an_observation_of_the_same_length_are_refused(tmp_path, capsys):
    """Gallery (13x11) and Gallery-Turned (11x13) have symbolic observations of one length whose
    entries name other cells: the networks are refused in one line, the critic alone transfers."""
    src = tmp_path / "src"
    assert main(["train", "gallery", "--out", str(src), "--steps", "300", "--no-progress", *CLI_TINY]) == 0
    capsys.readouterr()
    out = tmp_path / "turned"
    assert main(["train", "gallery_turned", "--init-from", str(src), "--out", str(out), "--steps", "300",
                 "--no-progress", *CLI_TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    assert "the grids differ in size: gallery is 13x11, gallery_turned 11x13; the symbolic observation" in err[0]
    assert not out.exists()
    assert main(["train", "gallery_turned", "--init-from", str(src), "--transfer", "critic", "--out", str(out),
                 "--steps", "300", "--no-progress", *CLI_TINY]) == 0
    assert yaml.safe_load((out / "config.yaml").read_text())["init_from"]["parts"] == ["critic"]


def test_other_observation_modes_are_refused_in_one_line(sources, tmp_path, capsys):
    out = tmp_path / "ego"
    assert main(["train", "keydoor_moved", "--init-from", str(sources["keydoor"]), "--out", str(out),
                 "--no-progress", "--set", "env.obs_mode=egocentric", *CLI_TINY]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["hubsgo: error: --init-from " + str(sources["keydoor"]) + ": observation modes differ: the source "
                   "run observes 'symbolic', this one 'egocentric'; set --set env.obs_mode=symbolic, or transfer "
                   "the critic alone (--transfer critic)"]
    assert not out.exists()
    assert main(["train", "keydoor_moved", "--restart-schedules", "--out", str(out), "--no-progress"]) == 2
    assert "add --init-from RUN" in capsys.readouterr().err



def _one_error_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("hubsgo: error: "), err
    return err[0]


def test_a_damaged_source_checkpoint_is_refused_in_one_line_before_anything_is_written(tmp_path, capsys):
    from hubsgo_ppl.experiments.io import save_torch

    src = tmp_path / "src"
    train(RunConfig(task="keydoor", steps=300, seed=0, overrides=TINY), src, progress=False)
    ckpt = load_checkpoint(src / "checkpoint.pt")
    del ckpt["agent"]["filter"]                     # a checkpoint its own config cannot restore
    save_torch(src / "checkpoint.pt", ckpt)
    out = tmp_path / "dst"
    assert main(["train", "keydoor_moved", "--init-from", str(src), "--steps", "300", "--out", str(out),
                 "--no-progress", *CLI_TINY]) == 2
    line = _one_error_line(capsys)
    assert "does not match its own config" in line and "start from another run" in line, line
    assert not (out / "checkpoint.pt").exists()


def test_a_folder_without_a_checkpoint_is_refused_without_advice_about_resume(tmp_path, capsys):
    src = tmp_path / "empty"
    src.mkdir()
    assert main(["train", "keydoor_moved", "--init-from", str(src), "--steps", "300", "--out", str(tmp_path / "dst"),
                 "--no-progress", *CLI_TINY]) == 2
    line = _one_error_line(capsys)
    assert "no checkpoint here" in line and "--resume" not in line, line


def test_egocentric_networks_moved_to_another_catalogue_get_a_note(tmp_path, capsys):
    ego = TINY + ["env.obs_mode=egocentric"]
    src = tmp_path / "src"
    train(RunConfig(task="keydoor", steps=300, seed=0, overrides=ego), src, progress=False)
    capsys.readouterr()
    for target, noted in (("fourroom", True), ("keydoor_moved", False)):
        # fourroom's five sub-goals give an observation of keydoor's length, each entry another sub-goal's
        cfg = RunConfig(task=target, steps=300, seed=0, overrides=ego, init_from=str(src))
        train(cfg, tmp_path / target, progress=False, max_episodes=0)
        err = capsys.readouterr().err
        assert ("the egocentric observation has entries per catalogue sub-goal" in err) == noted, err


def test_a_transfer_between_families_names_the_critic_instead_of_an_obs_mode_the_target_lacks(tmp_path, capsys):
    pytest.importorskip("robosuite")
    src = tmp_path / "maze"
    train(RunConfig(task="keydoor", steps=300, seed=0, overrides=TINY), src, progress=False)
    capsys.readouterr()
    base = ["train", "push_any_one", "--init-from", str(src), "--steps", "300", "--no-progress"]
    assert main([*base, "--out", str(tmp_path / "arm")]) == 2
    line = _one_error_line(capsys)
    assert "only a critic could transfer; transfer the critic alone (--transfer critic)" in line, line
    assert "obs_mode" not in line, line
    assert main([*base, "--transfer", "critic,high", "--out", str(tmp_path / "arm2")]) == 2
    line = _one_error_line(capsys)
    assert "cannot transfer the high" in line and "obs_mode" not in line, line
    assert not (tmp_path / "arm").exists() or not (tmp_path / "arm" / "checkpoint.pt").exists()
