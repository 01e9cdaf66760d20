"""Default hyperparameters per task family, overridable from the CLI (``--set loop.option_steps=30``).

:func:`hubsgo_ppl.agents.config.resolve_hyper` merges them with a task's own settings and the
overrides, and validates the result against the runtime settings classes."""

from __future__ import annotations

import copy
from typing import Any

__all__ = ["PRESETS", "TASK_PRESETS", "preset", "apply_overrides"]

PRESETS: dict[str, dict[str, Any]] = {
    "minigrid": {
        # One default for every maze, shipped or written by a user (docs/results.md, "Critic evidence
        # and defaults"); nothing maze-specific lives here.
        "steps": 40_000,
        "low_level": "learned",
        "env": {},                      # keyword arguments of the env, e.g. max_steps
        # the high level reads Ĝt given what the agent holds and has opened, once per episode until
        # that changes; before the critic's first update Ĝt is the prior's completion of what was
        # achieved; the critic is updated on every 4th high-level minibatch (the pool at weight 1/4);
        # after each update from evidence the learned low level's TD loss weighs each sub-goal by its
        # marginal, at least 1 - filter_end (h-DQN, without a critic: all alike)
        "loop": {"option_steps": 10, "explore_fraction": 0.3, "low_explore_fraction": 0.3,
                 "filter_start": 0.5, "filter_end": 0.9, "filter_fraction": 0.3,
                 "filter_given_achieved": True, "filter_refresh": "episode", "filter_before_update": "completion",
                 "critic_every": 4, "low_goal_weight": "marginal"},
        "high": {"hidden": [128, 128], "lr": 1e-3, "batch_size": 64},
        # potential-based shaping towards each sub-goal's cell (optimal policies unchanged)
        "low": {"hidden": [128, 128], "lr": 5e-4, "batch_size": 128, "learning_starts": 1000, "shaping": 1.0},
        # flat baselines (Stable-Baselines3 keyword arguments; agents/flat.py). dqn and ddqn share "dqn".
        "dqn": {"learning_rate": 5e-4, "buffer_size": 100_000, "learning_starts": 1000, "batch_size": 64,
                "train_freq": 4, "target_update_interval": 1000, "exploration_fraction": 0.3,
                "exploration_final_eps": 0.05, "gamma": 0.99, "policy_kwargs": {"net_arch": [256, 256]}},
        "ppo": {"learning_rate": 3e-4, "n_steps": 1024, "batch_size": 64, "n_epochs": 4, "gamma": 0.99,
                "ent_coef": 0.01, "policy_kwargs": {"net_arch": [128, 128]}},
        # HIRO (agents/hiro.py, HIROConfig); goals are (dx, dy) cell offsets
        "hiro": {"c": 10, "hidden": [128, 128], "lr": 3e-4, "batch_size": 64, "low_learning_starts": 1000,
                 "temperature": 0.3, "high_noise": 0.3},
    },
    "robosuite": {
        "steps": 20_000,                # StackCubes needs ~20k; PushAnyOne 8k, CollectThreeBalls 12k suffice
        "low_level": "scripted",
        "env": {},                      # e.g. {horizon: 300}; the catalogue's options are the defaults
        # 60 steps fit any single scripted sub-goal (measured <= 45 for grasp/place, pushes continue over
        # two options); shorter options give the high level more decisions per env step
        "loop": {"option_steps": 60, "explore_fraction": 0.3, "filter_fraction": 0.3,
                 # the scripted controller ignores these; they scale GoalTD3's exploration noise
                 "low_explore_start": 1.0, "low_explore_end": 0.3, "low_explore_fraction": 0.5},
        "high": {"hidden": [128, 128], "lr": 1e-3, "batch_size": 32, "learning_starts": 32},
        "low": {},                      # ScriptedOSC (scripted) or GoalTD3Config (learned) fields
        "td3": {"learning_rate": 1e-3, "buffer_size": 100_000, "learning_starts": 1000, "batch_size": 256,
                "train_freq": 1, "gamma": 0.99, "noise_sigma": 0.1, "policy_kwargs": {"net_arch": [256, 256]}},
        # goals are end-effector offsets (m) within +-goal_scale
        "hiro": {"c": 10, "hidden": [256, 256], "lr": 3e-4, "batch_size": 128, "low_learning_starts": 1000,
                 "goal_scale": 0.3, "low_noise": 0.1},
    },
}


# Per-task settings merged over the family's: the arm tasks' horizons and budgets (docs/results.md).
# Mazes have none: every maze trains on the MiniGrid family default.
TASK_PRESETS: dict[str, dict[str, Any]] = {
    "stack_cubes": {"steps": 20_000, "env": {"horizon": 400}, "loop": {"option_steps": 40}},
    "push_any_one": {"steps": 8_000, "env": {"horizon": 200}},
    "collect_three_balls": {"steps": 12_000, "env": {"horizon": 600}},
}


def _merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    for k, v in extra.items():
        base[k] = _merge(base.get(k, {}), v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return base


def preset(family: str, task: str | None = None) -> dict[str, Any]:
    """The family's defaults, with the task's own settings (if any) merged over them."""
    if family not in PRESETS:
        raise KeyError(f"no hyperparameter preset for task family {family!r}")
    return _merge(copy.deepcopy(PRESETS[family]), copy.deepcopy(TASK_PRESETS.get(task or "", {})))


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
