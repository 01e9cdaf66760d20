"""One configuration system for the agents' hyperparameters.

A run's settings are the task family's preset (:mod:`.presets`) with the task's own settings and the
``--set section.key=value`` overrides merged over it (:func:`resolve_hyper`). Each section an agent
reads is validated by a pydantic model (:func:`section_model`) generated from its runtime settings
class, so field names, types and defaults are written once:

=========  =====================================================================================
section    runtime settings
=========  =====================================================================================
``loop``   :class:`~.loop.LoopConfig` (HRL loop; ``total_steps`` comes from ``steps``)
``high``   :class:`~.high_level.HighLevelConfig`
``low``    :class:`~.low_level.GoalDQNConfig` (grids), :class:`~.scripted_maze.ScriptedMaze` (scripted
           grid low level), :class:`~.td3_her.GoalTD3Config` (learned arm low level) or
           :class:`~.scripted_osc.ScriptedOSC` (scripted arm low level)
``hiro``   :class:`~.hiro.HIROConfig` (``total_steps`` comes from ``steps``)
``dqn``,   keyword arguments of Stable-Baselines3's DQN, PPO, TD3 (names only), plus ``unit_steps``
``ppo``,   (:mod:`.flat`) and, for ``td3``, ``noise_sigma``
``td3``
=========  =====================================================================================

The builders make their runtime settings with :func:`make_config`, the same models, so an unknown or
mistyped key is reported in one line naming the section, the key and the valid keys wherever it is
found. A value written ``3e-4`` (YAML reads it as text) is a number for a numeric setting. Ranges are
checked by the runtime classes themselves (``__post_init__``).
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import types
import typing
from typing import Annotated, Any, Sequence, Union

from pydantic import BeforeValidator, StrictBool, StrictFloat, StrictInt, StrictStr, ValidationError, create_model

from ..specs import StrictModel
from .presets import apply_overrides, preset

__all__ = ["ConfigError", "section_model", "section_classes", "validate_section", "make_config",
           "resolve_hyper", "HIERARCHICAL", "SB3_SECTIONS"]

#: the agents that run the HRL loop (sections loop, high, low)
HIERARCHICAL = ("hubsgo", "hdqn")
#: flat baselines -> the preset section holding their Stable-Baselines3 arguments
SB3_SECTIONS = {"dqn": "dqn", "ddqn": "dqn", "ppo": "ppo", "td3": "td3"}
#: settings of a flat baseline's section that are the trainer's, not SB3's
_SB3_EXTRA = {"dqn": ("unit_steps",), "ppo": ("unit_steps",), "td3": ("unit_steps", "noise_sigma")}
#: SB3 constructor arguments the trainer sets itself
_SB3_FIXED = {"policy", "env", "seed", "verbose", "device", "_init_setup_model"}
#: set by the builders from the run's ``steps``, never in a section
_DERIVED = {"total_steps"}


class ConfigError(ValueError):
    """A setting is unknown or of the wrong kind; ``section``/``key`` name it (section None: top level)."""

    def __init__(self, message: str, section: str | None, key: str):
        super().__init__(message)
        self.section, self.key = section, key


# -- value types -------------------------------------------------------------------------------------


def _number(text: Any) -> Any:
    """``"3e-4"`` (text to YAML) -> 0.0003; anything else unchanged."""
    if isinstance(text, str):
        try:
            return float(text)
        except ValueError:
            return text
    return text


def _integer(text: Any) -> Any:
    """``"1e5"`` -> 100000; a text that is not a whole number stays text (and is refused)."""
    value = _number(text)
    return int(value) if isinstance(value, float) and isinstance(text, str) and value.is_integer() else text


def _any_number(text: Any) -> Any:
    """For a setting of any kind (SB3's arguments): a number written as text becomes an int if it is
    whole (``"1e5"``), else a float (``"3e-4"``); other values are unchanged."""
    value = _integer(text)
    return _number(value) if isinstance(value, str) else value


Int = Annotated[StrictInt, BeforeValidator(_integer)]
Float = Annotated[StrictFloat, BeforeValidator(_number)]
AnyValue = Annotated[Any, BeforeValidator(_any_number)]
_TYPES = {bool: StrictBool, int: Int, float: Float, str: StrictStr}
_KINDS = {bool: "true or false", int: "an integer", float: "a number", str: "a string", tuple: "a list, e.g. [64, 64]"}


def _field_type(hint: Any) -> tuple[Any, str | None]:
    """(pydantic type, the kind in words) of a settings annotation."""
    if hint in _TYPES:
        return _TYPES[hint], _KINDS[hint]
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is tuple:
        inner = _field_type(args[0])[0] if args else Any
        return tuple[inner, ...], _KINDS[tuple]
    if origin in (Union, types.UnionType) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        if len(rest) == 1:
            inner, kind = _field_type(rest[0])
            return inner | None, f"{kind} or null" if kind else None
    return Any, None


def _fields_of(cls: type) -> dict[str, tuple[Any, Any]]:
    """``{name: (annotation, default)}`` of a settings dataclass or of a class's keyword arguments."""
    if dataclasses.is_dataclass(cls):
        hints = typing.get_type_hints(cls)
        return {f.name: (hints[f.name], f.default) for f in dataclasses.fields(cls) if f.name not in _DERIVED}
    hints = typing.get_type_hints(cls.__init__)
    params = inspect.signature(cls.__init__).parameters.values()
    return {p.name: (hints.get(p.name, Any), p.default) for p in params
            if p.name != "self" and p.kind is p.POSITIONAL_OR_KEYWORD and p.default is not p.empty}


@functools.cache
def section_model(section: str, cls: type) -> type[StrictModel]:
    """The pydantic model of ``section`` whose runtime settings are ``cls`` (unknown keys are refused)."""
    fields, kinds = {}, {}
    for name, (hint, default) in _fields_of(cls).items():
        typ, kinds[name] = _field_type(hint)
        fields[name] = (typ, default)
    model = create_model(f"{section.title()}Settings", __base__=StrictModel, **fields)
    model.kinds = kinds                 # type: ignore[attr-defined]
    return model


@functools.cache
def _sb3_model(section: str) -> type[StrictModel]:
    import stable_baselines3 as sb3

    algo = getattr(sb3, section.upper())
    names = [p for p in inspect.signature(algo.__init__).parameters if p != "self" and p not in _SB3_FIXED]
    fields = {name: (AnyValue, None) for name in [*names, *_SB3_EXTRA[section]]}
    model = create_model(f"{section.upper()}Settings", __base__=StrictModel, **fields)
    model.kinds = {}                    # type: ignore[attr-defined]
    return model


def _all_fields(cls: type) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) else set()


# -- validation --------------------------------------------------------------------------------------


def validate_section(section: str, model: type[StrictModel], values: dict[str, Any], agent: str | None = None,
                     defaults: dict[str, Any] | None = None) -> dict[str, Any]:
    """The section's settings, validated (numbers written as text converted, lists made tuples);
    only the keys given. Raises :class:`ConfigError` naming the first bad key. ``section=""``: the
    run's own settings (outside every section); ``defaults``: the defaults to name (the model's)."""
    if not isinstance(values, dict):
        raise ConfigError(f"section {section!r} must be a mapping of settings, got {values!r}", None, section)
    try:
        parsed = model.model_validate(values)
    except ValidationError as exc:
        err = exc.errors()[0]
        key = str(err["loc"][0])
        if err["type"] == "extra_forbidden":
            who = f" (agent {agent})" if agent else ""
            raise ConfigError(f"unknown key {key!r} in section {section!r}{who}; valid keys: "
                              f"{', '.join(sorted(model.model_fields))}", section, key) from None
        kind = model.kinds.get(key) or "a valid value"      # type: ignore[attr-defined]
        default = (defaults or {}).get(key, model.model_fields[key].default)
        raise ConfigError(f"{section + '.' if section else ''}{key} takes {kind} (default {default!r}), "
                          f"got {values[key]!r}", section or None, key) from None
    out = {k: getattr(parsed, k) for k in values}
    for key, value in out.items():
        problem = _out_of_bounds(key, value)
        if problem:
            default = (defaults or {}).get(key, model.model_fields[key].default)
            raise ConfigError(f"{section + '.' if section else ''}{key} must be {problem} (default {default!r}), "
                              f"got {values[key]!r}", section or None, key)
    return out


#: bounds of the settings of these names, in whichever section they appear: (lowest, highest, whether
#: the lowest itself is allowed); None: no bound. A value past them would hang a loop, divide by zero
#: or fill the networks with NaN.
_BOUNDS = {"option_steps": (1, None, True), "batch_size": (1, None, True), "buffer_size": (1, None, True),
           "train_freq": (1, None, True), "target_update_interval": (1, None, True), "n_steps": (1, None, True),
           "n_epochs": (1, None, True), "learning_starts": (0, None, True), "lr": (0, None, False),
           "learning_rate": (0, None, False), "gamma": (0, 1, True), "tau": (0, 1, False)}


def _out_of_bounds(key: str, value: Any) -> str | None:
    """What ``value`` of the setting ``key`` must be, where it is not; None where it is fine."""
    if isinstance(value, float) and not math.isfinite(value):
        return "a finite number"
    if isinstance(value, bool) or not isinstance(value, (int, float, tuple)):
        return None
    if key == "hidden" and isinstance(value, tuple):
        return "a list of positive layer sizes" if any(not isinstance(h, int) or h < 1 for h in value) else None
    if isinstance(value, tuple):
        return None
    if key.endswith("_fraction") and not 0 < value <= 1:
        return "in (0, 1]"
    if key.startswith(("explore_", "low_explore_", "filter_start", "filter_end")) and not 0 <= value <= 1:
        return "in [0, 1]"
    lo, hi, closed = _BOUNDS.get(key, (None, None, True))
    if lo is not None and (value < lo or (value == lo and not closed)):
        return f"{'at least' if closed else 'above'} {lo}" + (f" and at most {hi}" if hi is not None else "")
    if hi is not None and value > hi:
        return f"at most {hi}" + (f" and {'at least' if closed else 'above'} {lo}" if lo is not None else "")
    return None


def make_config(section: str, cls: type, values: dict[str, Any], **derived: Any) -> Any:
    """``cls(**settings, **derived)`` from a section's validated settings (``derived``: values the
    builder sets itself, such as ``total_steps``)."""
    return cls(**validate_section(section, section_model(section, cls), dict(values)), **derived)


def section_classes(agent: str, family: str, low_level: str) -> dict[str, type]:
    """``{section: runtime settings class}`` of the sections ``agent`` reads (others it ignores)."""
    if agent in HIERARCHICAL:
        from .high_level import HighLevelConfig
        from .loop import LoopConfig

        if low_level == "scripted" and family == "minigrid":
            from .scripted_maze import ScriptedMaze as low
        elif low_level == "scripted":
            from .scripted_osc import ScriptedOSC as low
        elif family == "minigrid":
            from .low_level import GoalDQNConfig as low
        else:
            from .td3_her import GoalTD3Config as low
        return {"loop": LoopConfig, "high": HighLevelConfig, "low": low}
    if agent == "hiro":
        from .hiro import HIROConfig

        return {"hiro": HIROConfig}
    return {}


def _models(agent: str, family: str, low_level: str) -> dict[str, type[StrictModel]]:
    models = {s: section_model(s, cls) for s, cls in section_classes(agent, family, low_level).items()}
    if agent in SB3_SECTIONS:
        models[SB3_SECTIONS[agent]] = _sb3_model(SB3_SECTIONS[agent])
    return models


#: the run's own settings (outside every section) that ``--set`` may change
_RUN = create_model("RunSettings", __base__=StrictModel, steps=(Int, None), low_level=(StrictStr, None))
_RUN.kinds = {"steps": _KINDS[int], "low_level": _KINDS[str]}      # type: ignore[attr-defined]


def _check_item(item: str, base: dict[str, Any], hyper: dict[str, Any], models: dict[str, type[StrictModel]],
                agent: str) -> None:
    """Validate one ``--set`` item against the merged settings ``hyper``; its value, validated, goes back
    into ``hyper``. Nested keys, and sections the agent does not read, are checked where they are used."""
    key, _, _ = item.partition("=")
    parts = key.strip().split(".")
    sections = sorted(k for k, v in base.items() if isinstance(v, dict))
    plain = sorted(k for k, v in base.items() if not isinstance(v, dict))
    if len(parts) == 1:
        name = parts[0]
        if name in sections:
            first = next(iter(models[name].model_fields), "KEY") if name in models else "KEY"
            raise ConfigError(f"{name!r} is a section; set one of its keys, e.g. {name}.{first}=VALUE", None, name)
        if name not in plain:
            raise ConfigError(f"unknown setting {name!r}; settings: {', '.join(plain)}; sections: "
                              f"{', '.join(sections)}", None, name)
        if name in _RUN.model_fields:
            hyper[name] = validate_section("", _RUN, {name: hyper[name]}, defaults=base)[name]
        return
    if len(parts) == 2 and parts[0] in models:
        section, name = parts
        model = models[section]
        value = validate_section(section, model, {name: hyper[section][name]}, agent,
                                 defaults=base.get(section))[name]      # the preset's value is the default here
        hyper[section][name] = model(**{name: value}).model_dump(mode="json", include={name})[name]


def set_keys(overrides: Sequence[str], section: str) -> set[str]:
    """The keys of ``section`` that the ``--set`` items ``overrides`` name (``loop.gamma=0.9`` -> gamma)."""
    prefix = section + "."
    return {key[len(prefix):] for key in (item.partition("=")[0].strip() for item in overrides)
            if key.startswith(prefix)}


def resolve_hyper(family: str, task: str | None, agent: str, overrides: list[str] = (), *,
                  steps: int | None = None, low_level: str | None = None) -> dict[str, Any]:
    """The run's settings: preset, task settings, ``steps``/``low_level`` and the ``--set`` overrides
    merged, each override validated, and every section ``agent`` reads checked whole (ranges included,
    by building its runtime settings). Errors are one line; those of an override start ``--set ITEM:``."""
    hyper = preset(family, task)
    if steps is not None:
        hyper["steps"] = int(steps)
    default_low = hyper.get("low_level")
    if low_level is not None:
        hyper["low_level"] = low_level
    base, hyper = hyper, apply_overrides(hyper, list(overrides))
    if hyper.get("low_level") != default_low and "low" in hyper:
        # the preset's low section is the family default low level's; another low level gets only what
        # --set gives it
        given = set_keys(overrides, "low")
        hyper["low"] = {k: v for k, v in hyper["low"].items() if k in given}
        base = {**base, "low": {k: v for k, v in base["low"].items() if k in given}}
    models = _models(agent, family, str(hyper.get("low_level", "learned")))
    for item in overrides:
        try:
            _check_item(item, base, hyper, models, agent)
        except ConfigError as exc:
            raise ConfigError(f"--set {item}: {exc}", exc.section, exc.key) from None
    classes = section_classes(agent, family, str(hyper.get("low_level", "learned")))
    for section, cls in classes.items():
        derived = {k: int(hyper["steps"]) for k in _DERIVED if k in _all_fields(cls)}
        try:        # the whole section: its preset keys, and ranges (checked by the settings class)
            make_config(section, cls, hyper.get(section, {}), **derived)
        except ValueError as exc:
            if not overrides:
                raise
            msg = " ".join(str(exc).split())
            raise ConfigError(f"the run cannot be built with --set {' --set '.join(overrides)}: {msg}",
                              section, "") from None
    return hyper
