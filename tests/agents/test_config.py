"""One home for the settings: the typed family defaults are what a run uses, every range is declared once
on the settings models, and a bad setting is refused in one line on every path."""

import dataclasses
import math
import re
from pathlib import Path

import annotated_types
import pytest

from hubsgo_ppl.agents.config import ConfigError, make_config, resolve_hyper, section_classes
from hubsgo_ppl.agents.factory import build_agent
from hubsgo_ppl.agents.presets import FAMILIES, PRESETS
from hubsgo_ppl.agents.settings import (GoalDQNConfig, GoalTD3Config, HighLevelConfig, HIROConfig, LoopConfig,
                                        ScriptedMazeConfig, ScriptedOSCConfig, Settings)
from hubsgo_ppl.envs import make, register

SECTIONS = [("loop", LoopConfig), ("high", HighLevelConfig), ("low", GoalDQNConfig), ("low", GoalTD3Config),
            ("low", ScriptedMazeConfig), ("low", ScriptedOSCConfig), ("hiro", HIROConfig)]


def _dump(model: Settings) -> dict:
    return model.model_dump()


def test_a_maze_run_is_built_from_the_typed_minigrid_defaults():
    register()
    hyper = resolve_hyper("minigrid", "keydoor", "hubsgo")
    assert hyper["steps"] == 40_000 and hyper["low_level"] == "learned"
    from hubsgo_ppl.infer.critic import SubgoalCritic
    from hubsgo_ppl.graph import SubgoalGraph

    env = make("keydoor")
    critic = SubgoalCritic(SubgoalGraph(list(env.unwrapped.subgoal_names), []), seed=0)
    loop = build_agent("hubsgo", env, hyper, seed=0, critic=critic)
    assert _dump(loop.cfg) == _dump(LoopConfig.minigrid()) | {"total_steps": 40_000}
    assert _dump(loop.high.cfg) == _dump(HighLevelConfig.minigrid())
    assert _dump(loop.low.cfg) == _dump(GoalDQNConfig.minigrid())
    # what the maze family changes from the class defaults, spelled out
    assert (loop.cfg.option_steps, loop.cfg.critic_every, loop.cfg.filter_refresh, loop.low.cfg.shaping) == \
        (10, 4, "episode", 1.0)


def test_an_arm_run_resolves_to_the_typed_robosuite_defaults_with_the_tasks_own():
    hyper = resolve_hyper("robosuite", "stack_cubes", "hubsgo")
    built = {s: make_config(s, cls, hyper[s], **({"total_steps": hyper["steps"]} if s == "loop" else {}))
             for s, cls in section_classes("hubsgo", "robosuite", hyper["low_level"]).items()}
    assert _dump(built["loop"]) == _dump(LoopConfig.robosuite()) | {"total_steps": 20_000}
    assert _dump(built["high"]) == _dump(HighLevelConfig.robosuite())
    assert _dump(built["low"]) == _dump(ScriptedOSCConfig())
    hiro = resolve_hyper("robosuite", "push_any_one", "hiro")
    assert _dump(make_config("hiro", HIROConfig, hiro["hiro"], total_steps=8_000)) == \
        _dump(HIROConfig.robosuite()) | {"total_steps": 8_000}


def test_the_dict_view_of_the_defaults_is_derived_from_the_typed_ones():
    for name, family in FAMILIES.items():
        assert PRESETS[name]["loop"] == family.loop.model_dump(mode="json", exclude_unset=True)
        assert PRESETS[name]["high"]["hidden"] == list(family.high.hidden)
    # a family's view holds exactly the keys its typed defaults set
    mine = dataclasses.replace(FAMILIES["minigrid"], loop=LoopConfig(option_steps=12))
    assert mine.as_dict()["loop"] == {"option_steps": 12}


def _just_past(bound):
    """A value just outside an annotated_types bound."""
    if isinstance(bound, annotated_types.Ge):
        return bound.ge - 1 if isinstance(bound.ge, int) else math.nextafter(bound.ge, -math.inf)
    if isinstance(bound, annotated_types.Le):
        return math.nextafter(bound.le, math.inf)
    return bound.gt if isinstance(bound, annotated_types.Gt) else bound.lt


@pytest.mark.parametrize("section, cls", SECTIONS)
def test_every_bounded_setting_is_refused_just_past_its_bound_in_one_line(section, cls):
    derived = {"total_steps": 5} if "total_steps" in cls.model_fields else {}
    checked = 0
    for key, field in cls.model_fields.items():
        for bound in field.metadata:
            if key == "total_steps" or not isinstance(bound, (annotated_types.Ge, annotated_types.Gt,
                                                               annotated_types.Le, annotated_types.Lt)):
                continue
            bad = _just_past(bound)
            with pytest.raises(ConfigError) as err:
                make_config(section, cls, {key: bad}, **derived)
            msg = str(err.value)
            assert "\n" not in msg and msg.startswith(f"{section}.{key} takes ") and msg.endswith(f"got {bad!r}"), msg
            assert f"(default {field.default!r})" in msg and err.value.key == key
            checked += 1
    assert checked >= 1


def test_ranges_are_declared_only_on_the_settings_models():
    """No runtime class re-checks a setting: no __post_init__, and no "KEY must be" for any settings key
    outside the settings module (the old checks in the runtime classes, the filter and the controllers)."""
    agents = Path(__import__("hubsgo_ppl.agents", fromlist=["x"]).__file__).parent
    keys = {k for _, cls in SECTIONS for k in cls.model_fields}
    for path in agents.glob("*.py"):
        if path.name != "settings.py":
            text = path.read_text(encoding="utf-8")
            assert "__post_init__" not in text, path.name
            found = [k for k in keys if re.search(rf"\b{k}\b[^\n]{{0,40}}must be", text)]
            assert not found, (path.name, found)


@pytest.mark.parametrize("item, message", [
    ("loop.nonsense=3", "--set loop.nonsense=3: unknown key 'nonsense' in section 'loop' (agent hubsgo); valid keys: "),
    ("loop.option_steps=0", "--set loop.option_steps=0: loop.option_steps takes an integer >= 1 (default 10), got 0"),
    ("loop.filter_end=1.5", "--set loop.filter_end=1.5: loop.filter_end takes a number in [0, 1] (default 0.9), got 1.5"),
    ("loop.filter_refresh=always", "--set loop.filter_refresh=always: loop.filter_refresh takes one of 'option', "
                                   "'episode' (default 'episode'), got 'always'"),
    ("high.lr=fast", "--set high.lr=fast: high.lr takes a finite number > 0 (default 0.001), got 'fast'"),
    ("high.double_q=2", "--set high.double_q=2: high.double_q takes true or false (default True), got 2"),
    ("low.hidden=[0]", "--set low.hidden=[0]: low.hidden takes a list of integers >= 1, e.g. [64, 64] (default [128, 128]), got [0]"),
    ("loop.settle_at=0", "--set loop.settle_at=0: loop.settle_at takes a number in (0, 1], or null (default 0.9), got 0"),
    ("loop.total_steps=5", "--set loop.total_steps=5: unknown key 'total_steps' in section 'loop' (agent hubsgo)"),
    ("steps=0", "--set steps=0: steps takes an integer >= 1 (default 40000), got 0"),
    ("steps=many", "--set steps=many: steps takes an integer >= 1 (default 40000), got 'many'"),
    ("low_level=magic", "--set low_level=magic: low_level takes one of 'learned', 'scripted' (default 'learned'), got 'magic'"),
])
def test_a_bad_setting_is_refused_in_one_line_naming_what_it_takes_and_its_default(item, message):
    with pytest.raises(ConfigError) as err:
        resolve_hyper("minigrid", "keydoor", "hubsgo", [item])
    assert str(err.value).startswith(message) and "\n" not in str(err.value), str(err.value)


def test_steps_are_checked_however_they_are_given():
    with pytest.raises(ConfigError, match=r"^steps takes an integer >= 1 \(default 40000\), got 0$"):
        resolve_hyper("minigrid", "keydoor", "hdqn", steps=0)
    assert resolve_hyper("minigrid", "keydoor", "hdqn", ["steps=1e3"])["steps"] == 1000


def test_make_config_validates_keys_and_kinds_in_one_line():
    with pytest.raises(ConfigError, match=r"^unknown key 'lrr' in section 'high'; valid keys: batch_size, .*, lr,"):
        make_config("high", HighLevelConfig, {"lrr": 0.1})
    with pytest.raises(ConfigError, match=r"^high.batch_size takes an integer >= 1 \(default 64\), got 2.5$"):
        make_config("high", HighLevelConfig, {"batch_size": 2.5})
    cfg = make_config("high", HighLevelConfig, {"lr": "3e-4", "buffer_size": "1e5", "hidden": [8, 8]})
    assert cfg.lr == 3e-4 and cfg.buffer_size == 100_000 and cfg.hidden == (8, 8)
    with pytest.raises(ConfigError, match=r"^low.gamma takes a number in \[0, 1\) \(default 0.95\), got 1.0$"):
        make_config("low", GoalTD3Config, {"gamma": 1.0})
    with pytest.raises(ConfigError, match=r"^high.lr takes a finite number > 0 \(default 0.001\), got inf$"):
        make_config("high", HighLevelConfig, {"lr": float("inf")})


def test_resolve_merges_preset_task_and_overrides():
    hyper = resolve_hyper("robosuite", "stack_cubes", "hubsgo", ["loop.gamma=1", "high.lr=3e-4"], steps=100)
    assert hyper["steps"] == 100 and hyper["env"]["horizon"] == 400            # the task's own setting
    assert hyper["loop"]["option_steps"] == 60                                     # the family's
    # the family's loop for its other low level (the learned one's slower pick-and-carry), unless --set
    learned = lambda *items: resolve_hyper("robosuite", "stack_cubes", "hubsgo", list(items), low_level="learned")
    assert learned()["loop"]["option_steps"] == 120 and learned()["low_level"] == "learned"
    assert learned("loop.option_steps=30")["loop"]["option_steps"] == 30
    assert resolve_hyper("minigrid", "keydoor", "hubsgo", [], low_level="scripted")["loop"]["option_steps"] == 10
    assert hyper["loop"]["gamma"] == 1.0 and hyper["high"]["lr"] == 3e-4
    assert set(section_classes("hubsgo", "robosuite", "scripted")) == {"loop", "high", "low"}
    # flat baselines: SB3's argument names, numbers written as text made numbers, the trainer's settings
    td3 = resolve_hyper("robosuite", "stack_cubes", "td3", ["td3.learning_rate=3e-4", "td3.noise_sigma=0.2",
                                                             "td3.unit_steps=1e3"])["td3"]
    assert td3["learning_rate"] == 3e-4 and td3["noise_sigma"] == 0.2 and td3["unit_steps"] == 1000
    with pytest.raises(ConfigError, match=r"--set ppo.nsteps=8: unknown key 'nsteps' in section 'ppo' "
                                          r"\(agent ppo\); valid keys: .*n_steps"):
        resolve_hyper("minigrid", "keydoor", "ppo", ["ppo.nsteps=8"])
    with pytest.raises(ConfigError, match=r"^--set dqn.gamma=2: dqn.gamma takes a number in \[0, 1\] \(default 0.99\)"):
        resolve_hyper("minigrid", "keydoor", "dqn", ["dqn.gamma=2"])
    # sections the agent does not read are kept, their keys checked all the same
    assert resolve_hyper("minigrid", "keydoor", "hdqn", ["hiro.c=3"])["hiro"]["c"] == 3
    with pytest.raises(ConfigError, match=r"^--set hiro.whatever=1: unknown key 'whatever' in section 'hiro';"):
        resolve_hyper("minigrid", "keydoor", "hdqn", ["hiro.whatever=1"])


@pytest.mark.parametrize("section", ["loop", "high", "low"])
def test_a_section_set_whole_is_refused_with_an_example_key_that_can_be_set(section):
    with pytest.raises(ConfigError) as err:
        resolve_hyper("minigrid", "keydoor", "hubsgo", [f"{section}=3"])
    example = re.search(r"e\.g\. (\S+)=VALUE", str(err.value)).group(1)
    try:
        resolve_hyper("minigrid", "keydoor", "hubsgo", [f"{example}=1"])
    except ConfigError as exc:          # a value it refuses is fine; the key itself must be one it takes
        assert "unknown key" not in str(exc), str(exc)


@pytest.mark.parametrize("family, agent, item, message", [
    ("minigrid", "hubsgo", "hiro.x=1", "unknown key 'x' in section 'hiro'; valid keys: .*"),
    ("minigrid", "hubsgo", "hiro.c=abc", "hiro.c takes an integer >= 1"),
    ("minigrid", "ppo", "dqn.bogus=1", "unknown key 'bogus' in section 'dqn'"),
    ("minigrid", "ppo", "loop.bogus=1", "unknown key 'bogus' in section 'loop'"),
    ("minigrid", "hiro", "high.lr=-1", "high.lr takes a finite number > 0"),
    ("robosuite", "hdqn", "td3.bogus=1", "unknown key 'bogus' in section 'td3'")])
def test_a_bad_key_of_a_section_the_agent_does_not_read_is_still_refused(family, agent, item, message):
    with pytest.raises(ConfigError, match=f"--set {re.escape(item)}: {message}"):
        resolve_hyper(family, None, agent, [item])


def test_a_good_key_of_a_section_the_agent_does_not_read_is_kept_for_a_sweep_s_other_agents():
    assert resolve_hyper("minigrid", None, "hubsgo", ["hiro.c=5"])["hiro"]["c"] == 5
    assert resolve_hyper("minigrid", None, "ppo", ["loop.option_steps=5"])["loop"]["option_steps"] == 5


def test_a_run_names_the_set_items_its_agent_does_not_read(capsys):
    from hubsgo_ppl.agents.config import unread_items
    from hubsgo_ppl.experiments.resolve import resolve
    from hubsgo_ppl.experiments.resolved import RunConfig

    assert unread_items("higl", "minigrid", "learned", ["hiro.c=5", "higl.c=5", "steps=9", "env.x=1"]) == ["hiro.c=5"]
    assert unread_items("hubsgo", "minigrid", "learned", ["low.lr=0.01", "ppo.n_steps=64"]) == ["ppo.n_steps=64"]
    resolve(RunConfig(task="keydoor", agent="higl", overrides=["hiro.c=5"]))
    assert "--set hiro.c=5: agent 'higl' reads none of it (its sections: higl)" in capsys.readouterr().err
    resolve(RunConfig(task="keydoor", agent="higl", overrides=["higl.c=5"]))
    assert "reads none of it" not in capsys.readouterr().err
