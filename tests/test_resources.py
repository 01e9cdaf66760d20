"""Where the shipped data is found: the package data after install, the top-level folders in a checkout."""

import importlib.util

import yaml

from hubsgo_ppl import resources
from hubsgo_ppl.resources import envs_dir, models_dir, sweeps_dir


def test_shipped_folders_hold_the_catalogues_specs_and_sweeps():
    assert (envs_dir() / "keydoor.yaml").is_file() and (envs_dir() / "keydoor.txt").is_file()
    layout = yaml.safe_load((envs_dir() / "keydoor.yaml").read_text())["options"]["layout"]
    assert (envs_dir() / layout).is_file()
    assert (models_dir() / "keydoor-specific.yaml").is_file()
    assert (sweeps_dir() / "table1.yaml").is_file()


def test_falls_back_to_the_repository_folders_without_the_data_packages(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name.startswith("hubsgo_ppl._") else real(name, *a))
    root = resources._REPO_ROOT
    assert (models_dir(), envs_dir(), sweeps_dir()) == (root / "models", root / "envs", root / "sweeps")
