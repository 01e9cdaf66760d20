"""The sweep report on a fixture sweep: table cells equal mean ± s.e. computed by hand from metrics.csv."""

import csv
import math
import re
import statistics
from pathlib import Path

import numpy as np
import pytest
import yaml

from hubsgo_ppl.experiments.report import PAPER, ReportError, curves, collect, write_report

VARIANTS = {"hubsgo-specific": "HUBS-GO (specific correlations)", "ppo": "PPO", "lonely": "lonely"}


def _metrics(path, steps, returns):
    path.mkdir(parents=True, exist_ok=True)
    with (path / "metrics.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["episode", "env_steps", "length", "success", "options", "explore_eps", "filter_eps", "return",
                    "wall_time"])
        for i, (s, r) in enumerate(zip(steps, returns)):
            w.writerow([i, s, 10, int(r > 0), 1, 0.1, 0.0, r, 0.5 * i])


@pytest.fixture
def sweep_dir(tmp_path):
    rng = np.random.default_rng(0)
    root = tmp_path / "sweep"
    expected = {}
    for task in ("fourroom", "keydoor"):
        for variant in VARIANTS:
            seeds = [0] if variant == "lonely" else [0, 1, 2]
            for seed in seeds:
                n = int(rng.integers(5, 30))
                steps = np.sort(rng.choice(np.arange(1, 1000), n, replace=False))
                steps[-1] = 1000
                rets = np.round(rng.random(n), 4)
                _metrics(root / task / variant / f"seed{seed}", steps.tolist(), rets.tolist())
                expected.setdefault((variant, task), []).append(statistics.fmean(rets.tolist()))
    spec = {"name": "fixture", "table": "table1", "seeds": [0, 1, 2],
            "tasks": [{"name": "fourroom", "steps": 1000}, {"name": "keydoor", "steps": 1000}],
            "variants": [{"name": v, "label": l, "agent": "ppo"} for v, l in VARIANTS.items()]}
    (root / "sweep.yaml").write_text(yaml.safe_dump(spec))
    return root, expected


def test_table_cells_are_mean_and_standard_error_of_per_run_averages(sweep_dir):
    root, expected = sweep_dir
    paths = write_report(root)
    md = paths["table"].read_text()
    ours = md.split("The paper's")[0]
    assert ("across seeds. Seeds per cell: fourroom/hubsgo-specific: 0, 1, 2 (3); fourroom/lonely: 0 (1); "
            "fourroom/ppo: 0, 1, 2 (3); keydoor/hubsgo-specific: 0, 1, 2 (3);") in ours
    for (variant, task), avgs in expected.items():
        line = next(l for l in ours.splitlines() if l.startswith(f"| {VARIANTS[variant]} |"))
        cell = line.strip("|").split("|")[1 + ["fourroom", "keydoor"].index(task)].strip()
        mean = statistics.fmean(avgs)
        if len(avgs) == 1:
            assert cell == f"{mean:.4f} (n=1)"
            continue
        se = statistics.stdev(avgs) / math.sqrt(len(avgs))
        m, s = map(float, re.fullmatch(r"(\S+) ± (\S+)", cell).groups())
        assert m == pytest.approx(mean, abs=5e-5) and s == pytest.approx(se, abs=5e-5)
    with paths["csv"].open() as fh:
        rows = list(csv.DictReader(fh))
    agg = {(r["variant"], r["task"]): r for r in rows if r["level"] == "aggregate"}
    for key, avgs in expected.items():
        assert float(agg[key]["avg_return"]) == pytest.approx(statistics.fmean(avgs), rel=1e-12)
        if len(avgs) > 1:
            assert float(agg[key]["se"]) == pytest.approx(statistics.stdev(avgs) / math.sqrt(len(avgs)), rel=1e-9)
    assert float(agg[("ppo", "keydoor")]["paper_mean"]) == PAPER["table1"]["PPO"]["keydoor"][0]
    assert sum(r["level"] == "run" for r in rows) == 2 * 7
    # the paper's numbers, for the rows it has, in the same layout
    assert "| PPO | 0.6664 ± 0.0083 | 0.7567 ± 0.0084 |" in md
    for task in ("fourroom", "keydoor"):
        assert paths[f"curve_{task}"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_every_row_of_the_shipped_paper_grids_has_the_papers_numbers():
    from hubsgo_ppl.experiments.sweep import load_sweep, plan

    for table in ("table1", "table2"):
        spec, _ = load_sweep(table)
        assert spec.table == table
        assert plan(spec, Path("unused"))
        assert {v.label for v in spec.variants} <= set(PAPER[table])      # every row the paper has a row for
        assert PAPER[table]["HIGL"]["keydoor"] == (0.5439, 0.0210)
        assert PAPER[table]["HIRO (cardinal actions)"] == {t: PAPER[table]["HIRO"][t] for t in ("fourroom", "keydoor")}
    assert PAPER["table1"]["HUBS-GO (specific, cardinal actions)"]["keydoor"] == (0.8763, 0.0053)


def test_learning_curves_bin_by_steps_and_carry_forward(tmp_path):
    root = tmp_path / "s"
    _metrics(root / "keydoor" / "a" / "seed0", [10, 20, 60, 100], [0.0, 1.0, 1.0, 0.0])
    _metrics(root / "keydoor" / "a" / "seed1", [30, 100], [0.2, 0.6])
    data = curves(collect(root), "keydoor", ["a"], bins=4)
    x, mean, se = data["a"]
    np.testing.assert_allclose(x, [12.5, 37.5, 62.5, 87.5])
    run0 = np.array([0.5, 0.5, 1.0, 0.0])           # bin 1 is empty: carried forward
    run1 = np.array([np.nan, 0.2, 0.2, 0.6])        # nothing before its first episode
    np.testing.assert_allclose(mean, np.nanmean(np.vstack([run0, run1]), 0))
    np.testing.assert_allclose(se[1:], np.std(np.vstack([run0, run1])[:, 1:], 0, ddof=1) / np.sqrt(2))
    assert np.isnan(se[0])                          # one run in the bin: no spread to draw


def test_a_curve_of_one_seed_is_named_so_and_has_no_band(tmp_path, monkeypatch):
    from hubsgo_ppl.experiments import report

    root = tmp_path / "s"
    _metrics(root / "keydoor" / "a" / "seed0", [10, 20, 60, 100], [0.0, 1.0, 1.0, 0.0])
    _, _, se = curves(collect(root), "keydoor", ["a"], bins=4)["a"]
    assert np.isnan(se).all()
    drawn = {}
    plot = report._plot
    monkeypatch.setattr(report, "_plot", lambda t, data, labels, path: drawn.update(labels) or plot(t, data, labels,
                                                                                                    path))
    paths = write_report(root)
    assert drawn == {"a": "a (1 seed)"}
    rows = list(csv.DictReader(open(paths["curves_csv"])))
    assert rows and {r["se"] for r in rows} == {""}


def test_report_errors_name_the_problem(tmp_path):
    with pytest.raises(ReportError, match="no such sweep directory"):
        write_report(tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(ReportError, match="no finished runs"):
        write_report(tmp_path / "empty")


def test_a_run_short_of_its_recorded_budget_is_left_out_and_named(sweep_dir, tmp_path):
    """A sweep still running (or interrupted): its short runs stay out of the cells and curves."""
    root, expected = sweep_dir
    short = root / "keydoor" / "ppo" / "seed2"
    (short / "config.yaml").write_text(yaml.safe_dump({"task": "keydoor", "hyper": {"steps": 5000}}))
    (root / "keydoor" / "ppo" / "seed0" / "config.yaml").write_text(yaml.safe_dump({"hyper": {"steps": 1000}}))
    notes = []
    paths = write_report(root, out=tmp_path / "rep", notes=notes)
    text = paths["table"].read_text()
    line = next(l for l in text.split("The paper's")[0].splitlines() if l.startswith("| PPO |"))
    m, s = map(float, re.fullmatch(r"(\S+) ± (\S+)", line.strip("|").split("|")[2].strip()).groups())
    kept = expected[("ppo", "keydoor")][:2]         # seeds 0 (finished: 1000 of 1000) and 1 (no config.yaml)
    assert m == pytest.approx(statistics.fmean(kept), abs=5e-5)
    assert s == pytest.approx(statistics.stdev(kept) / math.sqrt(2), abs=5e-5)
    assert "keydoor/ppo/seed2 at 1,000 of 5,000 env steps" in text
    assert len(notes) == 1 and "left out 1 run(s)" in notes[0]
    from hubsgo_ppl.experiments.io import save_torch

    save_torch(short / "checkpoint.pt", {"format": 1, "env_steps": 5000})   # a flat agent stops mid-episode:
    assert "seed2" not in write_report(root, out=tmp_path / "rep2")["table"].read_text()  # its last row is short
    (short / "checkpoint.pt").unlink()
    for seed in (0, 1):
        (root / "keydoor" / "ppo" / f"seed{seed}" / "config.yaml").write_text(yaml.safe_dump({"hyper": {"steps": 5000}}))
    only = tmp_path / "only"
    (only / "keydoor").mkdir(parents=True)
    (root / "keydoor" / "ppo").rename(only / "keydoor" / "ppo")
    with pytest.raises(ReportError, match="no finished runs.*3 still short of their budget"):
        write_report(only)


def test_report_limited_to_one_grid_of_a_shared_folder(sweep_dir, tmp_path):
    """--sweep: only that grid's tasks, variants and seeds, with its labels, whatever else ran there."""
    root, _ = sweep_dir
    grid = {"name": "subset", "table": "table1", "seeds": [0, 1],
            "tasks": [{"name": "keydoor", "steps": 1000}],
            "variants": [{"name": "hubsgo-specific", "label": "HS", "agent": "hubsgo"}]}
    path = tmp_path / "subset.yaml"
    path.write_text(yaml.safe_dump(grid))
    paths = write_report(root, out=tmp_path / "rep", sweep=path)
    ours = paths["table"].read_text().split("The paper's")[0]
    avgs = [statistics.fmean(float(r["return"]) for r in csv.DictReader((root / "keydoor" / "hubsgo-specific" / f"seed{s}" / "metrics.csv").open()))
            for s in (0, 1)]
    line = next(l for l in ours.splitlines() if l.startswith("| HS |"))
    m, s = map(float, re.fullmatch(r"(\S+) ± (\S+)", line.strip("|").split("|")[1].strip()).groups())
    assert m == pytest.approx(statistics.fmean(avgs), abs=5e-5)
    assert s == pytest.approx(statistics.stdev(avgs) / math.sqrt(2), abs=5e-5)
    assert "fourroom" not in ours and "PPO" not in ours and "lonely" not in ours
    with paths["csv"].open() as fh:
        assert sum(r["level"] == "run" for r in csv.DictReader(fh)) == 2


def test_with_a_grid_a_run_trained_at_another_budget_is_left_out_and_named(sweep_dir, tmp_path):
    """--sweep: a run whose config.yaml records another budget than the grid's (a smaller trial run into
    the same folder) is never mixed into a cell."""
    root, expected = sweep_dir
    grid = {"name": "subset", "table": "table1", "seeds": [0, 1, 2], "tasks": [{"name": "keydoor", "steps": 1000}],
            "variants": [{"name": "ppo", "label": "PPO", "agent": "ppo"}]}
    path = tmp_path / "subset.yaml"
    path.write_text(yaml.safe_dump(grid))
    other = root / "keydoor" / "ppo" / "seed1"
    (other / "config.yaml").write_text(yaml.safe_dump({"task": "keydoor", "hyper": {"steps": 800}}))
    notes = []
    text = write_report(root, out=tmp_path / "rep", sweep=path, notes=notes)["table"].read_text()
    line = next(l for l in text.split("The paper's")[0].splitlines() if l.startswith("| PPO |"))
    m, s = map(float, re.fullmatch(r"(\S+) ± (\S+)", line.strip("|").split("|")[1].strip()).groups())
    kept = [expected[("ppo", "keydoor")][k] for k in (0, 2)]
    assert m == pytest.approx(statistics.fmean(kept), abs=5e-5)
    assert s == pytest.approx(statistics.stdev(kept) / math.sqrt(2), abs=5e-5)
    assert "trained at another budget than their cell's (1): keydoor/ppo/seed1 at 800 env steps" in text
    assert any("another budget" in n for n in notes)
    grid["seeds"] = [1]                              # every run at another budget: the error says so
    path.write_text(yaml.safe_dump(grid))
    with pytest.raises(ReportError, match="no finished runs.*1 trained at another budget"):
        write_report(root, out=tmp_path / "rep2", sweep=path)


def test_without_a_grid_a_cell_keeps_the_budget_most_of_its_finished_runs_record(sweep_dir, tmp_path):
    """No --sweep: a run trained at another budget than most of its cell's (a trial run into the same
    folder) is left out and named; on a tie the larger budget is kept."""
    root, expected = sweep_dir
    cell = root / "keydoor" / "ppo"
    for seed, steps in ((0, 1000), (1, 800), (2, 1000)):
        (cell / f"seed{seed}" / "config.yaml").write_text(yaml.safe_dump({"hyper": {"steps": steps}}))
    text = write_report(root, out=tmp_path / "rep")["table"].read_text()
    line = next(l for l in text.split("The paper's")[0].splitlines() if l.startswith("| PPO |"))
    m, _ = map(float, re.fullmatch(r"(\S+) ± (\S+)", line.strip("|").split("|")[2].strip()).groups())
    assert m == pytest.approx(statistics.fmean(expected[("ppo", "keydoor")][k] for k in (0, 2)), abs=5e-5)
    assert "another budget than their cell's (1): keydoor/ppo/seed1 at 800 env steps" in text
    (cell / "seed2" / "config.yaml").write_text(yaml.safe_dump({"hyper": {"steps": 800}}))
    (cell / "seed0" / "config.yaml").unlink()                # no budget recorded: never left out
    text = write_report(root, out=tmp_path / "rep2")["table"].read_text()
    assert "Left out, trained at another budget" not in text
    (cell / "seed0" / "config.yaml").write_text(yaml.safe_dump({"hyper": {"steps": 1000}}))
    (cell / "seed1").rename(tmp_path / "moved")               # one run at 1000, one at 800: the larger is kept
    text = write_report(root, out=tmp_path / "rep3")["table"].read_text()
    assert "(1): keydoor/ppo/seed2 at 800 env steps" in text


def test_steps_to_success_is_the_first_episode_end_where_the_rolling_rate_reaches_the_threshold():
    from hubsgo_ppl.experiments.report import steps_to_success

    steps = np.arange(1, 31) * 100                       # episode i ends at 100 (i + 1)
    succ = np.zeros(30)
    assert steps_to_success(steps, succ) is None
    succ[5:] = 1                                         # episodes 5..29 succeed
    # window of 20 ending at episode e holds e - 4 successes for e in 19..24: 18 (90%) first at e = 22
    assert steps_to_success(steps, succ) == 2300
    assert steps_to_success(steps, succ, rate=1.0) == 2500   # 20/20 first at e = 24
    assert steps_to_success(steps[:19], np.ones(19)) is None  # fewer episodes than the window


def test_the_success_table_counts_seeds_at_90_percent_and_reads_g_star(tmp_path):
    import json

    root = tmp_path / "sweep"
    n = 40
    for seed, first in ((0, 0), (1, 10), (2, n)):        # seed 2 never succeeds
        run = root / "keydoor" / "hubsgo-specific" / f"seed{seed}"
        _metrics(run, list(range(100, 100 * (n + 1), 100)), [0.0] * first + [0.9] * (n - first))
        top = ["key", "goal"] if seed < 2 else ["goal"]
        (run / "subgoals.json").write_text(json.dumps({"ranking": [{"subgoals": top, "prob": 0.8}]}))
    md = (write_report(root, out=tmp_path / "rep")["table"]).read_text()
    row = next(line for line in md.splitlines() if line.startswith("| keydoor |"))
    # seed 0 reaches 18/20 at episode 19 (step 2000); seed 1 at episode 27 (step 2800): 2400 ± 400
    assert "| 2,400 ± 400 | 2/3 |" in row
    # last 10% of 4000 steps: episodes ending at >= 3600 (5 episodes): 1, 1, 0 -> 0.6667 ± 0.3333
    assert "0.6667 ± 0.3333" in row
    assert "{key, goal} 2/3; {goal} 1/3" in row


def test_a_run_folder_without_an_episode_logged_is_named_not_dropped_silently(sweep_dir, tmp_path):
    """A run killed (or still starting) before its first episode ended: named like a run short of its budget."""
    root, _ = sweep_dir
    late = root / "keydoor" / "ppo" / "seed3"
    late.mkdir()
    (late / "config.yaml").write_text(yaml.safe_dump({"task": "keydoor", "hyper": {"steps": 1000}}))
    (late / "metrics.csv").write_text("episode,env_steps,length,success,options,explore_eps,filter_eps,return\n")
    (root / "fourroom" / "ppo" / "seed4").mkdir()
    notes = []
    text = write_report(root, out=tmp_path / "rep", notes=notes)["table"].read_text()
    assert "no episode logged yet (2; " in text and "fourroom/ppo/seed4, keydoor/ppo/seed3." in text
    assert notes == ["left out 2 run(s) with no episode logged yet (results.md names them)"]
    grid = tmp_path / "grid.yaml"
    grid.write_text(yaml.safe_dump({"name": "g", "seeds": [0, 1, 2, 3], "tasks": [{"name": "keydoor", "steps": 1000}],
                                    "variants": [{"name": "ppo", "agent": "ppo"}]}))
    text = write_report(root, out=tmp_path / "rep2", sweep=grid)["table"].read_text()
    assert "no episode logged yet (1; " in text and "keydoor/ppo/seed3." in text and "seed4" not in text


def test_cells_of_the_same_seeds_state_them_once(tmp_path):
    for variant in ("a", "b"):
        for seed in (0, 1, 4):
            _metrics(tmp_path / "sweep" / "keydoor" / variant / f"seed{seed}", [500, 1000], [0.0, 1.0])
    md = write_report(tmp_path / "sweep")["table"].read_text()
    assert "across seeds. Seeds: 0, 1, 4 (3) in every cell." in md and "Seeds per cell" not in md


def test_a_cell_whose_runs_were_trained_with_other_settings_reports_the_ones_most_runs_share(tmp_path):
    from hubsgo_ppl.experiments import RunConfig, train

    fast = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=100000", "low.hidden=[16]",
            "high.hidden=[16]"]
    for seed, option_steps in ((0, 15), (1, 15), (2, 5)):
        train(RunConfig(task="fourroom", agent="hdqn", seed=seed, steps=1,
                        overrides=[*fast, f"loop.option_steps={option_steps}"]),
              tmp_path / f"fourroom/hdqn/seed{seed}", progress=False)
    notes: list[str] = []
    paths = write_report(tmp_path, notes=notes)
    md = paths["table"].read_text()
    assert "Seeds: 0, 1 (2) in every cell." in md
    assert "Left out, trained with other settings than their cell's runs (1): fourroom/hdqn/seed2." in md
    assert any("other settings" in n for n in notes)
    rows = [r for r in csv.DictReader(paths["csv"].open()) if r["level"] == "aggregate"]
    assert [r["n"] for r in rows] == ["2"]
