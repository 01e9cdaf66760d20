"""scripts/measure_common.py: an --out folder remembers the settings its runs were made with."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
import measure_common  # noqa: E402  (a script module, not a package)
import measure_revise  # noqa: E402
import measure_transfer  # noqa: E402


def test_an_out_folder_records_its_settings_and_refuses_others(tmp_path):
    settings = {"steps": 15_000, "overrides": ["loop.filter_keep=0"], "threshold": 0.2, "keep_linked": False}
    measure_common.guard_settings(tmp_path, "measure_revise", settings)
    recorded = json.loads((tmp_path / measure_common.SETTINGS).read_text())
    assert recorded == {"script": "measure_revise", **settings}
    measure_common.guard_settings(tmp_path, "measure_revise", dict(settings))      # the same: accepted
    other = dict(settings, overrides=[], keep_linked=True)
    with pytest.raises(measure_common.SettingsMismatch) as err:
        measure_common.guard_settings(tmp_path, "measure_revise", other)
    msg = str(err.value)
    assert "\n" not in msg
    assert "--steps 15000 --set loop.filter_keep=0 --threshold 0.2" in msg
    assert msg.endswith("not --steps 15000 --threshold 0.2 --keep-linked; re-run with those settings or choose another --out")
    assert json.loads((tmp_path / measure_common.SETTINGS).read_text()) == recorded      # left as it was
    with pytest.raises(measure_common.SettingsMismatch, match="measure_transfer: .* holds runs made with"):
        measure_common.guard_settings(tmp_path, "measure_transfer", settings)           # another script's folder


def test_an_unreadable_settings_file_is_refused_in_one_line(tmp_path):
    (tmp_path / measure_common.SETTINGS).write_text("{not json")
    with pytest.raises(measure_common.SettingsMismatch, match="is unreadable; remove it if"):
        measure_common.guard_settings(tmp_path, "measure_transfer", {"steps": None, "overrides": []})


@pytest.mark.parametrize("script, extra", [(measure_revise, ["--keep-linked"]), (measure_transfer, ["--restart-schedules"])])
def test_the_scripts_refuse_an_out_made_with_other_settings_before_running_anything(tmp_path, monkeypatch, script, extra):
    ran = []
    monkeypatch.setattr(script, "run_jobs", lambda one, jobs, workers: ran.append(jobs) or [])
    monkeypatch.setattr(script, "finish", lambda rows, out, summarise: 0)
    out = tmp_path / "out"
    assert script.main(["--out", str(out), "--steps", "900", "--seeds", "0"]) == 0
    assert script.main(["--out", str(out), "--steps", "900", "--seeds", "1", "2"]) == 0    # more seeds: fine
    assert len(ran) == 2
    for argv in (["--steps", "1000"], ["--steps", "900", "--set", "loop.option_steps=5"], ["--steps", "900", *extra]):
        with pytest.raises(SystemExit, match=r"holds runs made with --steps 900( --threshold 0\.2)?, not "):
            script.main(["--out", str(out), *argv])
    assert len(ran) == 2


def test_finish_adds_the_rows_of_new_seeds_to_the_earlier_table_and_replaces_re_measured_ones(tmp_path, capsys):
    def row(seed, arm, steps):
        return {"task": "keydoor_incorrect", "seed": seed, "arm": arm, "steps_to_90": steps, "final_success": 1.0}

    summarise = measure_revise.summarise
    first = [row(s, a, 1000.0 * (s + 1)) for s in (0, 1) for a in measure_revise.ARMS]
    for r in first:
        r.update(total_steps_to_90=r["steps_to_90"], late_return=0.9, first_success=100.0, failures_after_pause=0.0,
                 settled_length=30.0, g_star_one_route=1.0, g_star_p=0.5)
    measure_common.finish(first, tmp_path, summarise)
    later = [dict(r, seed=2, steps_to_90=3000.0) for r in first if r["seed"] == 0]
    again = [dict(r, steps_to_90=9999.0) for r in first if r["seed"] == 1 and r["arm"] == "revised"]
    measure_common.finish(later + again, tmp_path, summarise)
    import csv

    with (tmp_path / "results.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    assert [(r["seed"], r["arm"]) for r in rows][:3] == [("0", a) for a in measure_revise.ARMS]
    assert len(rows) == 9 and {r["seed"] for r in rows} == {"0", "1", "2"}
    by = {(r["seed"], r["arm"]): float(r["steps_to_90"]) for r in rows}
    assert by[("1", "revised")] == 9999.0 and by[("1", "restart")] == 2000.0 and by[("2", "unrevised")] == 3000.0
    assert "| keydoor_incorrect | revised | 3 |" in (tmp_path / "summary.md").read_text()


def test_paired_lines_compare_two_arms_seed_by_seed_and_name_the_seeds_only_one_reached():
    nan = float("nan")
    steps = {"revised": [1000.0, 2000.0, 3000.0, nan, 5000.0], "unrevised": [1500.0, 2000.0, 2500.0, 4000.0, nan]}
    rows = [{"task": "kd", "seed": s, "arm": arm, "total_steps_to_90": v}
            for arm, vs in steps.items() for s, v in enumerate(vs)]
    lines = measure_common.paired_lines(rows, lambda r: r["task"], [("revised", "unrevised")], "total_steps_to_90", "task")
    assert len(lines) == 3 and lines[0].startswith("| task | comparison |")
    # differences over seeds 0-2: -500, 0, +500 -> mean 0, s.e. 500/sqrt(3) = 289
    assert lines[2] == "| kd | revised vs unrevised | 3 of 5 | 0 ± 289 | 1 | 1 | 1 | unrevised in seed 3, revised in seed 4 |"
    assert measure_common.paired_lines(rows, lambda r: r["task"], [("revised", "restart")], "total_steps_to_90")[2:] == []


def test_the_revision_summary_ends_with_the_paired_comparisons(tmp_path):
    rows = []
    for s in range(3):
        for arm, v in (("revised", 900.0 + s), ("unrevised", 1000.0), ("restart", 1000.0 + 100 * s)):
            rows.append({"task": "kd", "seed": s, "arm": arm, "total_steps_to_90": v, "steps_to_90": v,
                         "final_success": 1.0, "late_return": 0.9, "first_success": 10.0, "failures_after_pause": 0.0,
                         "settled_length": 30.0, "g_star_one_route": 1.0, "g_star_p": 0.5})
    text = measure_revise.summarise(rows, tmp_path / "summary.md")
    assert "| kd | revised vs unrevised | 3 of 3 | -99 ± 1 | 3 | 0 | 0 | - |" in text
    assert "| kd | revised vs restart | 3 of 3 | -199 ± 57 | 3 | 0 | 0 | - |" in text
    assert (tmp_path / "summary.md").read_text() == text
