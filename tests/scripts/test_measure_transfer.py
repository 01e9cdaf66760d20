"""scripts/measure_transfer.py: which runs each (pair, seed) makes, and how each target arm is configured."""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
import measure_transfer  # noqa: E402  (a script module, not a package)


@pytest.fixture
def recorded(monkeypatch):
    """``train`` replaced by one that records its config and writes a metrics.csv of 30 successes."""
    import hubsgo_ppl.experiments.io as io
    import hubsgo_ppl.experiments.run as run

    made = {}

    def fake_train(cfg, out, progress=True):
        out.mkdir(parents=True)
        made[out.name] = cfg
        with open(out / "metrics.csv", "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["episode", "env_steps", "length", "success", "return"])
            for i in range(30):
                w.writerow([i, 50 * (i + 1), 50, 1, 0.9])

    def no_checkpoint(*args, **kwargs):
        raise FileNotFoundError

    monkeypatch.setattr(run, "train", fake_train)
    monkeypatch.setattr(io, "load_checkpoint", no_checkpoint)
    return made


def test_each_arm_transfers_its_parts_and_continues_the_schedules_unless_told(tmp_path, recorded):
    rows = measure_transfer.one("keydoor", 3, tmp_path, 2_000, ["env.obs_mode=egocentric"])
    assert [r["arm"] for r in rows] == list(measure_transfer.ARMS)
    assert all(r["steps_to_90"] == 20 * 50 and r["target"] == "keydoor_moved" for r in rows)
    src = recorded["source"]
    assert (src.task, src.seed, src.steps, src.init_from) == ("keydoor", 3, 2_000, None)
    for arm, parts in measure_transfer.ARMS.items():
        cfg = recorded[arm]
        assert cfg.task == "keydoor_moved" and cfg.overrides == ["env.obs_mode=egocentric"]
        assert cfg.transfer == parts and (cfg.init_from is None) == (parts is None)
        assert cfg.restart_schedules == (arm == "all_restarted"), arm


def test_restart_and_arms_restrict_what_is_run(tmp_path, recorded):
    rows = measure_transfer.one("fourroom", 0, tmp_path, None, [], restart=True,
                                arms=("scratch", "all", "all_restarted"))
    assert [r["arm"] for r in rows] == ["scratch", "all"]          # all_restarted would repeat all
    assert set(recorded) == {"source", "scratch", "all"}
    assert recorded["all"].restart_schedules and recorded["all"].transfer == ["critic", "high", "low"]


def test_source_overrides_reach_the_source_run_only(tmp_path, recorded):
    measure_transfer.one("vault", 1, tmp_path, 2_000, ["env.obs_mode=egocentric"], arms=("scratch", "all"),
                         source_overrides=("env.start=room",))
    assert recorded["source"].overrides == ["env.obs_mode=egocentric", "env.start=room"]
    assert recorded["scratch"].overrides == recorded["all"].overrides == ["env.obs_mode=egocentric"]


def test_an_out_folder_remembers_its_source_overrides(tmp_path, monkeypatch):
    ran = []
    monkeypatch.setattr(measure_transfer, "run_jobs", lambda one, jobs, workers: ran.append(jobs) or [])
    monkeypatch.setattr(measure_transfer, "finish", lambda rows, out, summarise: 0)
    out = tmp_path / "out"
    argv = ["--out", str(out), "--steps", "900", "--seeds", "0", "--sources", "vault"]
    assert measure_transfer.main([*argv, "--source-set", "env.start=room"]) == 0
    assert ran[0][0][-1] == ("env.start=room",)
    with pytest.raises(SystemExit, match="holds runs made with --steps 900 --source-set env.start=room, not --steps 900;"):
        measure_transfer.main(argv)
