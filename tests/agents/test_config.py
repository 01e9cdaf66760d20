"""One configuration system: the pydantic section models mirror the runtime settings, and the
preset, the task's settings and --set merge and validate in one place."""

import dataclasses

import pytest

from hubsgo_ppl.agents.config import ConfigError, make_config, resolve_hyper, section_classes, section_model
from hubsgo_ppl.agents.high_level import HighLevelConfig
from hubsgo_ppl.agents.hiro import HIROConfig
from hubsgo_ppl.agents.loop import LoopConfig
from hubsgo_ppl.agents.low_level import GoalDQNConfig
from hubsgo_ppl.agents.td3_her import GoalTD3Config


@pytest.mark.parametrize("section, cls", [("loop", LoopConfig), ("high", HighLevelConfig), ("low", GoalDQNConfig),
                                          ("low", GoalTD3Config), ("hiro", HIROConfig)])
def test_section_models_mirror_the_runtime_settings(section, cls):
    model = section_model(section, cls)
    want = {f.name: f.default for f in dataclasses.fields(cls) if f.name != "total_steps"}
    assert {k: f.default for k, f in model.model_fields.items()} == want
    assert make_config(section, cls, {}, **({"total_steps": 5} if section in ("loop", "hiro") else {})) == \
        cls(**({"total_steps": 5} if section in ("loop", "hiro") else {}))


def test_make_config_validates_keys_and_kinds_in_one_line():
    with pytest.raises(ConfigError, match=r"^unknown key 'lrr' in section 'high'; valid keys: batch_size, .*, lr,"):
        make_config("high", HighLevelConfig, {"lrr": 0.1})
    with pytest.raises(ConfigError, match=r"^high.batch_size takes an integer \(default 64\), got 2.5$"):
        make_config("high", HighLevelConfig, {"batch_size": 2.5})
    cfg = make_config("high", HighLevelConfig, {"lr": "3e-4", "buffer_size": "1e5", "hidden": [8, 8]})
    assert cfg.lr == 3e-4 and cfg.buffer_size == 100_000 and cfg.hidden == (8, 8)
    with pytest.raises(ValueError, match="critic_pool_weight must be 'mean' or 'sum'"):   # ranges: the class's
        make_config("loop", LoopConfig, {"critic_pool_weight": "max"}, total_steps=10)


def test_resolve_merges_preset_task_and_overrides():
    hyper = resolve_hyper("robosuite", "stack_cubes", "hubsgo", ["loop.gamma=1", "high.lr=3e-4"], steps=100)
    assert hyper["steps"] == 100 and hyper["loop"]["option_steps"] == 40          # the task's own setting
    assert hyper["loop"]["gamma"] == 1.0 and hyper["high"]["lr"] == 3e-4
    assert set(section_classes("hubsgo", "robosuite", "scripted")) == {"loop", "high", "low"}
    # flat baselines: SB3's argument names, numbers written as text made numbers, the trainer's settings
    td3 = resolve_hyper("robosuite", "stack_cubes", "td3", ["td3.learning_rate=3e-4", "td3.noise_sigma=0.2",
                                                             "td3.unit_steps=1e3"])["td3"]
    assert td3["learning_rate"] == 3e-4 and td3["noise_sigma"] == 0.2 and td3["unit_steps"] == 1000
    with pytest.raises(ConfigError, match=r"--set ppo.nsteps=8: unknown key 'nsteps' in section 'ppo' "
                                          r"\(agent ppo\); valid keys: .*n_steps"):
        resolve_hyper("minigrid", "keydoor", "ppo", ["ppo.nsteps=8"])
    # sections the agent does not read are left as they are
    assert resolve_hyper("minigrid", "keydoor", "hdqn", ["hiro.whatever=1"])["hiro"]["whatever"] == 1
