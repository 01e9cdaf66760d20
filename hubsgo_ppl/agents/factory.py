"""Builds an agent by name. The two hierarchical agents share the HRL loop and differ only in
their filter (and low level):

- ``hubsgo``: the HRL loop + :class:`CriticFilter` around a :class:`SubgoalCritic` built from a model spec;
- ``hdqn``:   the same loop and sub-goals with :class:`NoFilter` (no critic).

:data:`BUILDERS` is a fixed table in this module, mapping each agent name to its builder. The two
hierarchical agents map to :func:`build_hierarchical`. The flat baselines (``ddqn``, ``dqn``, ``ppo``,
``td3``), HIRO (which has its own loop, :mod:`hubsgo_ppl.agents.hiro`) and HIGL (HIRO with landmarks,
:mod:`hubsgo_ppl.agents.higl`) map to a
``"module:function"`` string that :func:`build_agent` imports on first use, so their dependencies
(SB3, ...) load only when that agent is built. Their modules do not register anything themselves; a
new agent is added by adding an entry here.
"""

from __future__ import annotations

from typing import Any, Callable

import gymnasium as gym
import numpy as np
import torch

from .config import AGENTS, HIERARCHICAL, make_config
from .filters import CriticFilter, NoFilter
from .high_level import HighLevelDQN
from .loop import HRLLoop
from .low_level import GoalDQN, ScriptedLowLevel
from .protocols import LowLevel
from .seeding import HIGH_LEVEL_STREAM, LOW_LEVEL_STREAM, NET_INIT_STREAM, stream_generator, stream_rng
from .settings import GoalDQNConfig, HighLevelConfig, LoopConfig, ScriptedMazeConfig, ScriptedOSCConfig

__all__ = ["BUILDERS", "build_agent", "agent_names", "HIERARCHICAL"]


def _low_level(kind: str, env: gym.Env, n_goals: int, low_cfg: dict, gen: torch.Generator,
               rng: np.random.Generator) -> LowLevel:
    obs_dim = int(np.prod(env.observation_space.shape))
    if kind == "learned" and isinstance(env.action_space, gym.spaces.Discrete):
        config = make_config("low", GoalDQNConfig, low_cfg)
        potential = getattr(env.unwrapped, "subgoal_potential", lambda: None)()
        if config.shaping and potential is None:
            from ..errors import RunError

            raise RunError(f"low.shaping={config.shaping:g} shapes the low level's reward with the env's "
                           f"subgoal_potential(), which {type(env.unwrapped).__name__} does not give: train with "
                           "--set low.shaping=0, or add subgoal_potential() to the env (docs/own_env.md)")
        return GoalDQN(obs_dim, n_goals, int(env.action_space.n), config, gen, rng, potential=potential)
    if kind == "scripted" and isinstance(env.action_space, gym.spaces.Discrete):
        from .scripted_maze import ScriptedMaze

        return ScriptedLowLevel(ScriptedMaze(**make_config("low", ScriptedMazeConfig, low_cfg).model_dump()))
    if kind == "scripted":
        from .scripted_osc import ScriptedOSC

        return ScriptedLowLevel(ScriptedOSC(**make_config("low", ScriptedOSCConfig, low_cfg).model_dump()))
    if kind == "learned":
        from .td3_her import GoalTD3

        return GoalTD3.for_env(env, low_cfg, gen, rng)
    raise ValueError(f"unknown low level {kind!r}; use 'learned' or 'scripted'")


def build_hierarchical(agent: str, env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> HRLLoop:
    n = len(env.unwrapped.subgoal_names)
    gen = stream_generator(seed, NET_INIT_STREAM)
    high_rng = stream_rng(seed, HIGH_LEVEL_STREAM)
    low_rng = stream_rng(seed, LOW_LEVEL_STREAM)
    obs_dim = int(np.prod(env.observation_space.shape))
    loop_cfg = make_config("loop", LoopConfig, cfg.get("loop", {}), total_steps=int(cfg["steps"]))
    high_cfg = make_config("high", HighLevelConfig, cfg.get("high", {}))
    high = HighLevelDQN(obs_dim, n, high_cfg, gen, high_rng)
    low = _low_level(cfg.get("low_level", "learned"), env, n, cfg.get("low", {}), gen, low_rng)
    if agent == "hubsgo":
        if critic is None:
            raise ValueError("the hubsgo agent needs a critic (built from a model spec)")
        filt = CriticFilter(critic, loop_cfg.outcome_window, loop_cfg.filter_keep, loop_cfg.filter_before_update)
    elif agent == "hdqn":
        filt = NoFilter()
    else:
        raise ValueError(f"{agent!r} is not a hierarchical agent")
    return HRLLoop(env, high, low, filt, loop_cfg, seed)


# name -> builder(env, cfg, seed, critic=None), or "module:function" naming one. Strings are imported
# by build_agent on first use, so a baseline's dependencies load only when that baseline is built.
BUILDERS: dict[str, Callable[..., Any] | str] = {
    "hubsgo": lambda env, cfg, seed, critic=None: build_hierarchical("hubsgo", env, cfg, seed, critic),
    "hdqn": lambda env, cfg, seed, critic=None: build_hierarchical("hdqn", env, cfg, seed, critic),
    "ddqn": "hubsgo_ppl.agents.flat:build_ddqn",
    "dqn": "hubsgo_ppl.agents.flat:build_dqn",
    "ppo": "hubsgo_ppl.agents.flat:build_ppo",
    "td3": "hubsgo_ppl.agents.flat:build_td3",
    "hiro": "hubsgo_ppl.agents.hiro:build_hiro",
    "higl": "hubsgo_ppl.agents.higl:build_higl",
}


if sorted(BUILDERS) != list(AGENTS):     # the names the command line offers (config.AGENTS), each built here
    raise ImportError(f"agents/factory.py builds {sorted(BUILDERS)}, but agents/config.py names {list(AGENTS)}")


def agent_names() -> list[str]:
    return list(AGENTS)


def build_agent(agent: str, env: gym.Env, cfg: dict[str, Any], seed: int, critic: Any = None) -> Any:
    if agent not in BUILDERS:
        raise ValueError(f"unknown agent {agent!r}; use one of: {', '.join(sorted(BUILDERS))}")
    builder = BUILDERS[agent]
    if isinstance(builder, str):
        import importlib

        module, func = builder.split(":")
        builder = getattr(importlib.import_module(module), func)
    return builder(env, cfg, seed, critic=critic)
