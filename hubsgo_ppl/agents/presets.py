"""Default hyperparameters per task family, overridable from the CLI (``--set loop.option_steps=30``)."""

from __future__ import annotations

import copy
from typing import Any

__all__ = ["PRESETS", "preset", "apply_overrides"]

PRESETS: dict[str, dict[str, Any]] = {
    "minigrid": {
        "steps": 150_000,
        "low_level": "learned",
        "loop": {"option_steps": 30, "explore_fraction": 0.3, "low_explore_fraction": 0.3,
                 "filter_fraction": 0.5},
        "high": {"hidden": [128, 128], "lr": 1e-3, "batch_size": 64},
        "low": {"hidden": [256, 256], "lr": 5e-4, "batch_size": 128, "learning_starts": 1000},
    },
    "robosuite": {
        "steps": 30_000,
        "low_level": "scripted",
        "loop": {"option_steps": 120, "explore_fraction": 0.3, "filter_fraction": 0.5,
                 "low_explore_start": 0.0, "low_explore_end": 0.0},
        "high": {"hidden": [128, 128], "lr": 1e-3, "batch_size": 32, "learning_starts": 32},
        "low": {},
    },
}


def preset(family: str) -> dict[str, Any]:
    if family not in PRESETS:
        raise KeyError(f"no hyperparameter preset for task family {family!r}")
    return copy.deepcopy(PRESETS[family])


def _coerce(text: str) -> Any:
    import yaml

    return yaml.safe_load(text)


def apply_overrides(cfg: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply ``section.key=value`` overrides (values parsed as YAML scalars/lists)."""
    cfg = copy.deepcopy(cfg)
    for item in overrides:
        if "=" not in item:
            raise ValueError(f"--set {item!r}: expected KEY=VALUE, e.g. loop.option_steps=30")
        key, value = item.split("=", 1)
        parts = key.strip().split(".")
        node = cfg
        for p in parts[:-1]:
            if p not in node or not isinstance(node[p], dict):
                raise ValueError(f"--set {item!r}: unknown section {p!r}; sections: {sorted(k for k, v in cfg.items() if isinstance(v, dict))}")
            node = node[p]
        node[parts[-1]] = _coerce(value)
    return cfg
