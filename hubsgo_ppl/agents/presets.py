"""Default settings per task family (:data:`FAMILIES`, typed), overridable from the CLI
(``--set loop.option_steps=30``).

:func:`hubsgo_ppl.agents.config.resolve_hyper` merges them with a task's own settings and the
overrides, and validates the result against the runtime settings classes."""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

from .settings import GoalDQNConfig, HighLevelConfig, HIGLConfig, HIROConfig, LoopConfig, ScriptedOSCConfig, Settings

__all__ = ["FamilyDefaults", "FAMILIES", "PRESETS", "TASK_PRESETS", "OTHER_LOW_STEPS", "preset", "apply_overrides"]


@dataclass(frozen=True)
class FamilyDefaults:
    """A task family's defaults, typed: the run's own settings, the sections of the hierarchical agents
    and HIRO and HIGL (their settings models), and the flat baselines' Stable-Baselines3 arguments (checked by
    :func:`~.settings.sb3_model` when a run is resolved)."""

    steps: int
    low_level: str                          # "learned" or "scripted"
    loop: LoopConfig
    high: HighLevelConfig
    low: Settings                           # the settings of the family's default low level
    hiro: HIROConfig
    higl: HIGLConfig
    sb3: dict[str, dict[str, Any]] = field(default_factory=dict)    # section -> SB3 keyword arguments
    env: dict[str, Any] = field(default_factory=dict)                # keyword arguments of the env
    # loop keys that differ when a run takes the family's other low level (``--low-level``)
    other_low_loop: dict[str, Any] = field(default_factory=dict)
    # where set, a task without a budget of its own (TASK_PRESETS) trains for this many episodes of its
    # horizon instead of ``steps`` (experiments.resolve)
    episodes: int | None = None

    def as_dict(self) -> dict[str, Any]:
        """The dict a run's settings start from: each section holds the keys the family sets."""
        def keys(model: Settings) -> dict[str, Any]:
            return model.model_dump(mode="json", exclude_unset=True)

        return {"steps": self.steps, "low_level": self.low_level, "env": copy.deepcopy(self.env),
                "loop": keys(self.loop), "high": keys(self.high), "low": keys(self.low),
                **copy.deepcopy(self.sb3), "hiro": keys(self.hiro), "higl": keys(self.higl)}


FAMILIES: dict[str, FamilyDefaults] = {
    # One default for every maze, shipped or written by a user (docs/results.md, "Critic evidence and
    # defaults"); nothing maze-specific lives here.
    "minigrid": FamilyDefaults(
        steps=40_000, low_level="learned", loop=LoopConfig.minigrid(), high=HighLevelConfig.minigrid(),
        low=GoalDQNConfig.minigrid(), hiro=HIROConfig.minigrid(), higl=HIGLConfig.minigrid(),
        # flat baselines (agents/flat.py); dqn and ddqn share "dqn"
        sb3={"dqn": {"learning_rate": 5e-4, "buffer_size": 100_000, "learning_starts": 1000, "batch_size": 64,
                     "train_freq": 4, "target_update_interval": 1000, "exploration_fraction": 0.3,
                     "exploration_final_eps": 0.05, "gamma": 0.99, "policy_kwargs": {"net_arch": [256, 256]}},
             "ppo": {"learning_rate": 3e-4, "n_steps": 1024, "batch_size": 64, "n_epochs": 4, "gamma": 0.99,
                     "ent_coef": 0.01, "policy_kwargs": {"net_arch": [128, 128]}}}),
    # The shipped tasks' budgets are their own (TASK_PRESETS; OTHER_LOW_STEPS with the learned low
    # level); a user's arm task trains for 100 episodes of its horizon, as many as the shipped tasks need
    # with either low level (docs/arms.md): ``steps`` is that budget at the scenes' default horizon, 500
    "robosuite": FamilyDefaults(
        steps=50_000, episodes=100, low_level="scripted", loop=LoopConfig.robosuite(), high=HighLevelConfig.robosuite(),
        low=ScriptedOSCConfig(), hiro=HIROConfig.robosuite(), higl=HIGLConfig.robosuite(),
        # the learned low level moves more slowly than the scripted controller: a pick-and-carry takes it
        # 90-115 steps where the scripted one takes at most 45 (docs/results.md, "robosuite arm tasks")
        other_low_loop={"option_steps": 120},
        sb3={"td3": {"learning_rate": 1e-3, "buffer_size": 100_000, "learning_starts": 1000, "batch_size": 256,
                     "train_freq": 1, "gamma": 0.99, "noise_sigma": 0.1, "policy_kwargs": {"net_arch": [256, 256]}},
             # SB3's own PPO defaults for continuous control, with the arms' 256x256 networks
             "ppo": {"learning_rate": 3e-4, "n_steps": 2048, "batch_size": 64, "n_epochs": 10, "gamma": 0.99,
                     "ent_coef": 0.0, "policy_kwargs": {"net_arch": [256, 256]}}}),
}

# Any Gymnasium env with discrete actions (envs/gym_task.py): the mazes' loop, high level and flat
# baselines, and their learned low level without shaping, which needs a potential a user's env lacks
FAMILIES["gym"] = FamilyDefaults(
    steps=40_000, low_level="learned", loop=LoopConfig.minigrid(), high=HighLevelConfig.minigrid(),
    low=GoalDQNConfig.gym(), hiro=HIROConfig.minigrid(), higl=HIGLConfig.minigrid(), sb3=FAMILIES["minigrid"].sb3)

#: the families' defaults as dicts (a view of :data:`FAMILIES`)
PRESETS: dict[str, dict[str, Any]] = {name: family.as_dict() for name, family in FAMILIES.items()}


# Per-task settings merged over the family's: the arm tasks' horizons and budgets (docs/results.md).
# Mazes have none: every maze trains on the MiniGrid family default.
TASK_PRESETS: dict[str, dict[str, Any]] = {
    "stack_cubes": {"steps": 20_000, "env": {"horizon": 400}},
    "push_any_one": {"steps": 8_000, "env": {"horizon": 200}},
    "collect_three_balls": {"steps": 12_000, "env": {"horizon": 600}},
}


# The shipped arm tasks' budgets with the family's other low level, the learned GoalTD3: it moves more
# slowly than the scripted controller, and these are the budgets its table was measured at (docs/results.md,
# "robosuite arm tasks"). ``--steps`` and ``--set steps`` still win.
OTHER_LOW_STEPS: dict[str, int] = {"stack_cubes": 25_000, "push_any_one": 15_000, "collect_three_balls": 50_000}


def _merge(base: dict[str, Any], extra: dict[str, Any]) -> dict[str, Any]:
    for k, v in extra.items():
        base[k] = _merge(base.get(k, {}), v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return base


def preset(family: str, task: str | None = None) -> dict[str, Any]:
    """The family's defaults, with the task's own settings (if any) merged over them."""
    if family not in PRESETS:
        raise KeyError(f"no hyperparameter preset for task family {family!r}")
    return _merge(FAMILIES[family].as_dict(), copy.deepcopy(TASK_PRESETS.get(task or "", {})))


def _coerce(text: str) -> Any:
    import yaml

    return yaml.safe_load(text)


def apply_overrides(cfg: dict[str, Any], overrides: list[str]) -> dict[str, Any]:
    """Apply ``section.key=value`` overrides (values parsed as YAML scalars/lists)."""
    cfg = copy.deepcopy(cfg)
    for item in overrides:
        if "=" not in item:
            raise ValueError(f"--set {item}: expected KEY=VALUE, e.g. loop.option_steps=30")
        key, value = item.split("=", 1)
        parts = key.strip().split(".")
        node, where = cfg, ""
        for p in parts[:-1]:
            if p not in node or not isinstance(node[p], dict):
                sections = ", ".join(sorted(k for k, v in node.items() if isinstance(v, dict))) or "none"
                of = f" of {where[:-1]}" if where else ""
                raise ValueError(f"--set {item}: unknown section {where + p!r}; sections{of}: {sections}")
            node, where = node[p], where + p + "."
        node[parts[-1]] = _coerce(value)
    return cfg
