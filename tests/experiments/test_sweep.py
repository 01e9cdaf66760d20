"""Sweeps: validation, the shipped grids, resume after a killed worker, and the Ray backend."""

import importlib.util
import shutil
from pathlib import Path

import pytest
import yaml

from hubsgo_ppl.experiments.logger import read_csv_rows
from hubsgo_ppl.experiments.run import RunConfig, RunError, train
from hubsgo_ppl.experiments.sweep import KILL_ENV, SweepSpec, check_jobs, load_sweep, plan, run_status, run_sweep
from hubsgo_ppl.specs import SpecError, validate_spec

FAST = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=100000", "low.hidden=[16]",
        "high.hidden=[16]", "loop.option_steps=15"]


def _write(tmp_path, **spec):
    base = {"name": "t", "seeds": [0], "checkpoint_steps": 1, "overrides": FAST,
            "tasks": [{"name": "fourroom", "steps": 1}], "variants": [{"name": "hdqn", "agent": "hdqn"}]}
    base.update(spec)
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(base))
    return path


def _rows(path):
    return [{k: v for k, v in r.items() if k != "wall_time"} for r in read_csv_rows(Path(path) / "metrics.csv")]


@pytest.mark.parametrize("change, message", [
    ({"variants": [{"name": "x", "agent": "a2c"}]}, r"variants\[0\].agent: .*unknown agent 'a2c'"),
    ({"variants": [{"name": "x", "agent": "hdqn", "tasks": ["maze"]}]}, "not columns of this sweep"),
    ({"variants": [{"name": "x", "agent": "hdqn"}, {"name": "x", "agent": "ppo"}]}, "duplicate name"),
    ({"tasks": [{"name": "fourroom", "steps": 0}]}, r"tasks\[0\].steps"),
    ({"tasks": [{"name": "mazz", "steps": 5}]}, r"tasks\[0\].name: unknown task 'mazz'"),
    ({"seeds": [0, 0]}, "seeds"),
    ({"variants": [{"name": "x", "agent": "hdqn", "task": "{task}_wrong"}]}, r"variants\[0\].task"),
    ({"budget": 3}, "budget: unknown key"),
    ({"variants": [{"name": "x", "agent": "hubsgo", "model": "{bogus}-specific"}]},
     r"variants\[0\].model: .*only \{task\} may be filled in"),
    ({"variants": [{"name": "x", "agent": "hdqn", "task": "{task"}]}, r"variants\[0\].task: .*only \{task\}"),
    ({"variants": [{"name": "x", "agent": "hdqn", "low_level": "magic"}]}, "unknown low level 'magic'"),
])
def test_bad_sweep_files_name_the_file_and_key(tmp_path, change, message):
    path = _write(tmp_path, **change)
    with pytest.raises(SpecError, match=message) as err:
        load_sweep(path)
    assert str(path) in str(err.value)


def test_shipped_grids(tmp_path):
    quick, _ = load_sweep("quick")
    jobs = plan(quick, tmp_path)
    assert len(jobs) == 2 * 6 * 3
    assert {j.config["task"] for j in jobs} == {"fourroom", "keydoor"}
    assert {j.config["agent"] for j in jobs} == {"hubsgo", "hdqn", "ddqn", "ppo"}
    assert {j.config["graph"] for j in jobs if j.config["agent"] == "hubsgo"} == {None, "independent"}
    # the fully connected row is the sign-free spec (the paper's setting), not the specific spec's signs on every pair
    assert {j.config["model"] for j in jobs if j.run_id.split("/")[1] == "hubsgo-fully_connected"} == {
        "fourroom-fully_connected", "keydoor-fully_connected"}
    t2, _ = load_sweep("table2")
    runs = {(j.run_id.split("/")[1], j.config["task"]) for j in plan(t2, tmp_path)}
    assert ("hubsgo-incorrect", "keydoor_incorrect") in runs and ("hdqn-incorrect", "fourroom_incorrect") in runs
    assert ("hdqn", "keydoor") in runs and ("hiro", "fourroom") in runs
    t1 = validate_spec(SweepSpec, yaml.safe_load((Path(_).parent / "table1.yaml").read_text()), "table1.yaml")
    assert [t.name for t in t1.tasks] == ["fourroom", "keydoor", "stack_cubes", "push_any_one", "collect_three_balls"]
    assert {v.agent for v in t1.variants} == {"hubsgo", "ddqn", "ppo", "td3", "hdqn", "hiro", "higl"}


def test_every_shipped_sweep_plans_and_the_ten_seed_grid_extends_the_acceptance_runs(tmp_path):
    from hubsgo_ppl.resources import sweeps_dir

    for f in sorted(sweeps_dir().glob("*.yaml")):
        spec, _ = load_sweep(f.stem)
        assert plan(spec, tmp_path), f.name
    # run into Table 1's folder, Table 2's grid reuses its runs and trains only the rows with incorrect sub-goals
    t1 = {j.run_id: j.config for j in plan(load_sweep("table1")[0], tmp_path)}
    t2 = {j.run_id: j.config for j in plan(load_sweep("table2")[0], tmp_path)}
    assert all(t2[k] == t1[k] for k in set(t1) & set(t2))
    assert {k.split("/")[1] for k in set(t2) - set(t1)} == {"hubsgo-incorrect", "hdqn-incorrect"}
    # run into the same folder, the ten-seed KeyDoor grid reuses the 5-seed acceptance runs as its seeds 0-4
    five = {j.run_id: j.config for j in plan(load_sweep("keydoor_acceptance")[0], tmp_path)}
    ten = {j.run_id: j.config for j in plan(load_sweep("keydoor_ten_seeds")[0], tmp_path)}
    assert len(ten) == 20 and set(five) < set(ten)
    assert all(ten[k] == five[k] for k in five)


def test_sweep_resumes_after_a_killed_worker(tmp_path, monkeypatch):
    """Every hierarchical agent on the other grid tasks (keydoor is in test_run), one worker killed twice."""
    path = _write(tmp_path, tasks=[{"name": "fourroom", "steps": 1}, {"name": "fourroom_incorrect", "steps": 1},
                                   {"name": "keydoor_incorrect", "steps": 1}, {"name": "keydoor", "steps": 6000}],
                  variants=[{"name": "hubsgo", "agent": "hubsgo", "model": "{task}-specific",
                             "tasks": ["fourroom", "fourroom_incorrect", "keydoor_incorrect"]},
                            {"name": "hdqn", "agent": "hdqn"}])
    out = tmp_path / "sweep"
    victim = "keydoor/hdqn/seed0"
    monkeypatch.setenv(KILL_ENV, victim)
    first = run_sweep(path, workers=2, out=out, progress=False)
    assert first["finished"] == 6 and first["skipped"] == 0 and first["retried"] == 1
    assert len(first["failed"]) == 1 and first["failed"][0].startswith(victim)
    assert "SIGKILL" in first["failed"][0]
    spec, _ = load_sweep(path)
    job = {j.run_id: j for j in plan(spec, out)}[victim]
    assert run_status(job) == "partial"            # the retry resumed, got one checkpoint further, died

    monkeypatch.delenv(KILL_ENV)
    second = run_sweep(path, workers=2, out=out, progress=False)
    assert (second["finished"], second["skipped"], second["retried"], second["failed"]) == (1, 6, 0, [])
    assert second["runs"][victim] == "finished" and all(s == "skipped" for r, s in second["runs"].items() if r != victim)
    rows = _rows(job.out)
    assert [int(r["episode"]) for r in rows] == list(range(len(rows))) and int(rows[-1]["env_steps"]) >= 6000
    reference = tmp_path / "uninterrupted"
    train(RunConfig(**job.config), reference, progress=False)
    assert rows == _rows(reference), "kill + resume must give the uninterrupted run's metrics"
    for run_id, status in second["runs"].items():
        assert (out / run_id / "checkpoint.pt").is_file() and (out / run_id / "learning_curve.png").is_file()
    third = run_sweep(path, workers=1, out=out, progress=False)
    assert (third["finished"], third["skipped"]) == (0, 7)


def test_a_sweep_reads_its_user_maze_and_spec_from_its_own_folder(tmp_path, monkeypatch):
    """Relative catalogue and spec paths in a sweep file are found beside it, from any working directory; the
    column's folder is the catalogue's stem, and the report finds it there."""
    from hubsgo_ppl.experiments.report import write_report
    from hubsgo_ppl.resources import envs_dir

    study, elsewhere = tmp_path / "study", tmp_path / "elsewhere"
    (study / "mazes").mkdir(parents=True)
    elsewhere.mkdir()
    for name in ("fourroom.yaml", "fourroom.txt"):
        shutil.copy(envs_dir() / name, study / "mazes" / name.replace("fourroom", "rooms"))
    cat = yaml.safe_load((study / "mazes" / "rooms.yaml").read_text())
    cat.update(task="rooms", options={**cat["options"], "layout": "rooms.txt"})
    (study / "mazes" / "rooms.yaml").write_text(yaml.safe_dump(cat))
    names = [g["name"] for g in cat["subgoals"]]
    (study / "rooms-spec.yaml").write_text(yaml.safe_dump({"name": "rooms-spec", "subgoals": names, "edges": []}))
    path = _write(study, tasks=[{"name": "mazes/rooms.yaml", "steps": 1}],
                  variants=[{"name": "hubsgo", "agent": "hubsgo", "model": "rooms-spec.yaml"},
                            {"name": "hdqn", "agent": "hdqn", "tasks": ["mazes/rooms.yaml"]}])
    monkeypatch.chdir(elsewhere)
    jobs = {j.run_id: j for j in plan(load_sweep(path)[0], tmp_path / "out", base=path.parent)}
    assert sorted(jobs) == ["rooms/hdqn/seed0", "rooms/hubsgo/seed0"]
    assert jobs["rooms/hubsgo/seed0"].config["task"] == str(study / "mazes" / "rooms.yaml")
    assert jobs["rooms/hubsgo/seed0"].config["model"] == str(study / "rooms-spec.yaml")
    result = run_sweep(path, workers=2, out=tmp_path / "out", progress=False)
    assert (result["finished"], result["failed"]) == (2, [])
    assert read_csv_rows(tmp_path / "out" / "rooms" / "hubsgo" / "seed0" / "metrics.csv")
    paths = write_report(tmp_path / "out")
    table = paths["table"].read_text()
    assert "curve_rooms" in paths and "| Algorithm | rooms |" in table and "| hubsgo | " in table
    (study / "mazes" / "other").mkdir()
    shutil.copy(study / "mazes" / "rooms.yaml", study / "mazes" / "other" / "rooms.yaml")
    clash = _write(study, tasks=[{"name": "mazes/rooms.yaml", "steps": 1}, {"name": "mazes/other/rooms.yaml", "steps": 1}])
    with pytest.raises(SpecError, match="would share a folder"):
        load_sweep(clash)


@pytest.mark.skipif(importlib.util.find_spec("ray") is None, reason="the ray extra is not installed")
def test_ray_backend_runs_a_two_run_grid(tmp_path):
    path = _write(tmp_path, seeds=[0, 1])
    out = tmp_path / "ray"
    result = run_sweep(path, backend="ray", workers=2, out=out, progress=False)
    assert (result["finished"], result["skipped"], result["failed"]) == (2, 0, [])
    for seed in (0, 1):
        assert read_csv_rows(out / "fourroom" / "hdqn" / f"seed{seed}" / "metrics.csv")
    assert _rows(out / "fourroom/hdqn/seed0") != _rows(out / "fourroom/hdqn/seed1")
    again = run_sweep(path, backend="local", workers=1, out=out, progress=False)
    assert (again["finished"], again["skipped"]) == (0, 2)


@pytest.mark.parametrize("variant, message", [
    ({"name": "x", "agent": "hubsgo", "model": "no-such-spec"}, "run fourroom/x/seed0 cannot start: no-such-spec"),
    ({"name": "x", "agent": "hdqn", "overrides": ["loop.nosuch=1"]},
     "run fourroom/x/seed0 cannot start: --set loop.nosuch=1: unknown key 'nosuch'"),
])
def test_a_run_of_the_grid_that_cannot_start_stops_the_sweep_before_any_run(tmp_path, variant, message):
    path = _write(tmp_path, variants=[{"name": "hdqn", "agent": "hdqn"}, variant])
    with pytest.raises(SpecError, match=message):
        run_sweep(path, out=tmp_path / "x", progress=False)
    assert not (tmp_path / "x").exists()


def test_bad_backend_and_workers(tmp_path):
    path = _write(tmp_path)
    with pytest.raises(RunError, match="unknown backend"):
        run_sweep(path, backend="slurm", out=tmp_path / "x", progress=False)
    with pytest.raises(RunError, match="at least 1"):
        run_sweep(path, workers=0, out=tmp_path / "x", progress=False)


def test_a_subset_of_the_grid_runs_only_its_rows_and_columns_and_the_rest_follows_into_the_same_folder(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    path = _write(tmp_path, tasks=[{"name": "fourroom", "steps": 1}, {"name": "keydoor", "steps": 1}],
                  variants=[{"name": "hdqn", "agent": "hdqn"}, {"name": "hubsgo", "agent": "hubsgo"}])
    out = tmp_path / "sweep"
    part = run_sweep(path, workers=1, out=out, progress=False, variants=["hubsgo"], tasks=["keydoor"])
    assert list(part["runs"]) == ["keydoor/hubsgo/seed0"] and part["finished"] == 1
    assert sorted(str(p.relative_to(out).parent) for p in out.rglob("metrics.csv")) == ["keydoor/hubsgo/seed0"]
    assert len(yaml.safe_load((out / "sweep.yaml").read_text())["variants"]) == 2   # the whole grid recorded
    rest = run_sweep(path, workers=1, out=out, progress=False)
    assert (rest["finished"], rest["skipped"]) == (3, 1)
    # a name the grid lacks: one line naming what it has, and nothing runs
    assert main(["sweep", str(path), "--out", str(tmp_path / "none"), "--variants", "hubsgo", "ppo",
                 "--no-progress"]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no variants named 'ppo'; its variants: hdqn, hubsgo" in err[0], err
    assert not (tmp_path / "none").exists()


@pytest.mark.parametrize("name", ["../../x", "/tmp/x", "a/b", "..", ".hidden", "a\\b"])
def test_a_sweep_name_must_be_a_plain_folder_name(tmp_path, name):
    path = _write(tmp_path, name=name)
    with pytest.raises(SpecError, match=r"name: .*is not a plain folder name") as err:
        load_sweep(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_run_folder_without_a_checkpoint_keeps_the_files_the_tool_did_not_write(tmp_path):
    from hubsgo_ppl.experiments.sweep_workers import run_job

    path = _write(tmp_path)
    job = plan(load_sweep(path)[0], tmp_path / "sweep")[0]
    run = Path(job.out)
    run.mkdir(parents=True)
    (run / "notes.txt").write_text("my notes")
    (run / "metrics.csv").write_text("episode,env_steps\n0,3\n")      # a partial log, before any checkpoint
    (run / "tb").mkdir()
    (run / "tb" / "mine.txt").write_text("kept")
    result = run_job(job)
    assert result["ok"], result
    assert (run / "notes.txt").read_text() == "my notes" and (run / "tb" / "mine.txt").read_text() == "kept"
    assert (run / "checkpoint.pt").is_file() and _rows(run)[0]["episode"] == "0"


def test_a_sweep_refuses_a_run_folder_whose_logs_outlived_its_checkpoint_as_train_does(tmp_path, capsys):
    """The guard of `train`: a folder without checkpoint.pt whose metrics.csv passes the second checkpoint
    lost it; the sweep refuses it in one line, does not retry it, and leaves every file in place."""
    from hubsgo_ppl.cli import main

    path = _write(tmp_path, checkpoint_steps=100)
    out = tmp_path / "sweep"
    run = out / "fourroom" / "hdqn" / "seed0"
    run.mkdir(parents=True)
    logs = "episode,env_steps,return\n" + "".join(f"{i},{100 * (i + 1)},0.0\n" for i in range(3))
    (run / "metrics.csv").write_text(logs)
    (run / "config.yaml").write_text("checkpoint_steps: 100\n")
    with pytest.raises(RunError, match="checkpoint.pt is missing"):      # what `train` says of this folder
        train(RunConfig(task="fourroom", agent="hdqn", steps=1, overrides=FAST, checkpoint_steps=100), run,
              progress=False)
    assert main(["sweep", str(path), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    lines = capsys.readouterr().out.strip().splitlines()
    assert "0 finished, 0 skipped (already done), 0 retried, 1 failed" in lines[0], lines
    assert len(lines) == 2 and lines[1].startswith("  failed: fourroom/hdqn/seed0: refused: ") and \
        "checkpoint.pt is missing, though metrics.csv reaches env step 300" in lines[1], lines
    assert (run / "metrics.csv").read_text() == logs and sorted(p.name for p in run.iterdir()) == \
        ["config.yaml", "metrics.csv"]


def test_the_seeds_of_a_grid_cell_train_in_lockstep_in_one_worker_each_as_it_would_alone(tmp_path):
    from hubsgo_ppl.experiments.sweep_workers import bundles

    path = _write(tmp_path, seeds=[0, 1, 2], tasks=[{"name": "keydoor", "steps": 300}],
                  variants=[{"name": "hdqn", "agent": "hdqn"}, {"name": "hubsgo", "agent": "hubsgo"},
                            {"name": "ppo", "agent": "ppo"}])
    jobs = plan(load_sweep(path)[0], tmp_path / "p")
    check_jobs(jobs, path)
    stacked = [j.lockstep for j in jobs]
    assert stacked == [True] * 6 + [False] * 3
    # the cells whose networks stack go to a worker whole; a flat baseline's seeds, which would run one
    # after another in one process, get a worker each
    assert [[j.run_id for j in b] for b in bundles(jobs, 2)] == [
        [f"keydoor/hdqn/seed{s}" for s in range(3)], [f"keydoor/hubsgo/seed{s}" for s in range(3)],
        *[[f"keydoor/ppo/seed{s}"] for s in range(3)]]
    assert [len(b) for b in bundles(jobs[:3], 2)] == [2, 1]      # one cell, two workers: split in two
    assert [len(b) for b in bundles(jobs[:1], 2)] == [1]
    out = tmp_path / "sweep"
    result = run_sweep(path, workers=1, out=out, progress=False, variants=["hubsgo"])
    assert result["finished"] == 3 and result["failed"] == []
    job = {j.run_id: j for j in plan(load_sweep(path)[0], out)}["keydoor/hubsgo/seed2"]
    train(RunConfig(**job.config), tmp_path / "alone", progress=False)
    assert _rows(job.out) == _rows(tmp_path / "alone")


def test_an_interrupted_lockstep_cell_stops_its_seeds_rather_than_train_each_alone(tmp_path, monkeypatch):
    # an orphaned worker (its sweep killed) is interrupted by stop_with_parent; it must not go on with
    # each seed of its cell alone, unseen and holding their locks, as it does after a refused folder
    from hubsgo_ppl.experiments import sweep_workers

    raised = []

    def interrupt_once(job):
        def hook(stats):
            if not raised:
                raised.append(job.run_id)
                raise KeyboardInterrupt
        return hook

    monkeypatch.setattr(sweep_workers, "_kill_hook", interrupt_once)
    path = _write(tmp_path, seeds=[0, 1], checkpoint_steps=100, tasks=[{"name": "fourroom", "steps": 3000}])
    jobs = plan(load_sweep(path)[0], tmp_path / "sweep")
    check_jobs(jobs, path)
    assert all(j.lockstep for j in jobs)
    results = sweep_workers.run_bundle(jobs)
    assert raised and [r["ok"] for r in results] == [False, False], results
    assert all("interrupted" in r["error"] and r.get("refused") for r in results), results
    assert all(run_status(j) != "finished" for j in jobs)


def test_a_grid_without_runs_is_refused_before_anything_is_written(tmp_path):
    path = _write(tmp_path, variants=[{"name": "hdqn", "agent": "hdqn", "tasks": []}])
    with pytest.raises(SpecError, match="variant 'hdqn': tasks is empty"):
        load_sweep(path)
    path = _write(tmp_path, tasks=[{"name": "fourroom", "steps": 1}, {"name": "keydoor", "steps": 1}],
                  variants=[{"name": "hdqn", "agent": "hdqn", "tasks": ["keydoor"]}, {"name": "ppo", "agent": "ppo"}])
    out = tmp_path / "sweep"
    with pytest.raises(SpecError, match="no run left: the variants hdqn run on none of the tasks fourroom"):
        run_sweep(path, workers=1, out=out, progress=False, variants=["hdqn"], tasks=["fourroom"])
    assert not out.exists()


@pytest.mark.parametrize("where", ["file", "file/sub"])
def test_a_sweep_or_report_folder_that_is_a_file_is_named_so(tmp_path, capsys, where):
    from hubsgo_ppl.cli import main

    (tmp_path / "file").write_text("mine")
    run = tmp_path / "sweep" / "fourroom" / "hdqn" / "seed0"       # a finished run without a recorded budget
    run.mkdir(parents=True)
    (run / "metrics.csv").write_text("episode,env_steps,return,success\n0,10,1.0,1\n")
    out = tmp_path / where
    assert main(["sweep", str(_write(tmp_path)), "--out", str(out), "--workers", "1", "--no-progress"]) == 2
    assert main(["report", str(tmp_path / "sweep"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(f"{out}: a file where a folder goes" in line for line in err), err
    assert (tmp_path / "file").read_text() == "mine"


def test_a_grid_edited_between_calls_is_refused_rather_than_mix_two_settings_in_a_cell(tmp_path):
    path = _write(tmp_path)
    out = tmp_path / "sweep"
    assert run_sweep(path, workers=1, out=out, progress=False)["finished"] == 1
    first = _rows(out / "fourroom/hdqn/seed0")
    # another setting for the column, and a new seed that would train under it beside the old one
    _write(tmp_path, seeds=[0, 1], tasks=[{"name": "fourroom", "steps": 1, "overrides": ["loop.option_steps=5"]}])
    with pytest.raises(SpecError, match=r"fourroom/hdqn/seed0 \(hyper.loop.option_steps\).*another --out"):
        run_sweep(path, workers=1, out=out, progress=False)
    assert not (out / "fourroom/hdqn/seed1").exists() and _rows(out / "fourroom/hdqn/seed0") == first
    # another budget: a finished run would be skipped at its old one, an interrupted one moved to it part way
    _write(tmp_path, seeds=[0, 1], tasks=[{"name": "fourroom", "steps": 2}])
    with pytest.raises(SpecError, match=r"seed0 \(a budget of 1, not this grid's 2\)"):
        run_sweep(path, workers=1, out=out, progress=False)
    assert not (out / "fourroom/hdqn/seed1").exists()
    # the grid as it was, with a seed added (and other checkpoints): the new seed runs, the old is skipped
    _write(tmp_path, seeds=[0, 1], checkpoint_steps=5)
    result = run_sweep(path, workers=1, out=out, progress=False)
    assert (result["finished"], result["skipped"]) == (1, 1)
