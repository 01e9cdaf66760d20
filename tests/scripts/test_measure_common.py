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
    settings = {"steps": 15_000, "overrides": ["loop.filter_fallback=mode"], "threshold": 0.2, "keep_linked": False}
    measure_common.guard_settings(tmp_path, "measure_revise", settings)
    recorded = json.loads((tmp_path / measure_common.SETTINGS).read_text())
    assert recorded == {"script": "measure_revise", **settings}
    measure_common.guard_settings(tmp_path, "measure_revise", dict(settings))      # the same: accepted
    other = dict(settings, overrides=[], keep_linked=True)
    with pytest.raises(measure_common.SettingsMismatch) as err:
        measure_common.guard_settings(tmp_path, "measure_revise", other)
    msg = str(err.value)
    assert "\n" not in msg
    assert "--steps 15000 --set loop.filter_fallback=mode --threshold 0.2" in msg
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
