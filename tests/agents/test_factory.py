"""The agent factory: names, lazy baseline builders, the two hierarchical agents and their errors."""

import importlib
import sys

import pytest
import torch

from hubsgo_ppl.agents.factory import BUILDERS, agent_names, build_agent, build_hierarchical
from hubsgo_ppl.agents.filters import NoFilter
from hubsgo_ppl.agents.low_level import GoalDQN
from hubsgo_ppl.agents.presets import apply_overrides, preset
from hubsgo_ppl.envs import make, register

SMALL = ["high.hidden=[8]", "low.hidden=[8]", "low.shaping=0"]


def _cfg():
    cfg = apply_overrides(preset("minigrid"), SMALL)
    cfg["steps"] = 100
    return cfg


@pytest.fixture
def env():
    register()
    e = make("keydoor")
    yield e
    e.close()


def test_agent_names_and_lazy_builders_resolve():
    assert agent_names() == ["ddqn", "dqn", "hdqn", "higl", "hiro", "hubsgo", "ppo", "td3"]
    for name in ("ddqn", "dqn", "ppo", "td3", "hiro", "higl"):
        module, func = BUILDERS[name].split(":")
        assert callable(getattr(importlib.import_module(module), func)), name


def test_hdqn_is_the_loop_without_a_filter_and_seeds_reproduce(env):
    a = build_agent("hdqn", env, _cfg(), seed=3)
    b = build_agent("hdqn", env, _cfg(), seed=3)
    c = build_agent("hdqn", env, _cfg(), seed=4)
    assert type(a).__name__ == "HRLLoop" and isinstance(a.filter, NoFilter) and isinstance(a.low, GoalDQN)
    assert a.cfg.total_steps == 100
    wa, wb, wc = (next(x.high.q.parameters()) for x in (a, b, c))
    assert torch.equal(wa, wb) and not torch.equal(wa, wc)


def test_errors_name_the_problem(env):
    with pytest.raises(ValueError, match="unknown agent 'sac'; use one of: ddqn, dqn, hdqn"):
        build_agent("sac", env, _cfg(), seed=0)
    with pytest.raises(ValueError, match="the hubsgo agent needs a critic"):
        build_agent("hubsgo", env, _cfg(), seed=0)
    with pytest.raises(ValueError, match="'ppo' is not a hierarchical agent"):
        build_hierarchical("ppo", env, _cfg(), seed=0)
    cfg = _cfg()
    cfg["low_level"] = "magic"
    with pytest.raises(ValueError, match="unknown low level 'magic'; use 'learned' or 'scripted'"):
        build_agent("hdqn", env, cfg, seed=0)


def test_a_baseline_module_loads_only_when_built(env):
    sys.modules.pop("hubsgo_ppl.agents.hiro", None)
    build_agent("hdqn", env, _cfg(), seed=0)
    assert "hubsgo_ppl.agents.hiro" not in sys.modules
    cfg = _cfg()
    cfg["hiro"].update(hidden=[8], batch_size=8)
    agent = build_agent("hiro", env, cfg, seed=0)
    assert type(agent).__module__ == "hubsgo_ppl.agents.hiro"
