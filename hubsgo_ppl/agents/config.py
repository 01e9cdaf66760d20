"""Resolving a run's settings: the task family's defaults (:mod:`.presets`), the task's own settings and
the ``--set section.key=value`` overrides merged (:func:`resolve_hyper`), each section an agent reads
checked against its settings model (:mod:`.settings`, where every range is declared).

An unknown or mistyped key, a value of the wrong kind or out of range is reported in one line naming
the section, the key, what it takes and its default, wherever it is found.
"""

from __future__ import annotations

from typing import Any, Sequence

from pydantic import create_model

from .presets import FAMILIES, OTHER_LOW_STEPS, apply_overrides, preset
from .settings import (DERIVED, ConfigError, choice, GoalDQNConfig, GoalTD3Config, HighLevelConfig, HIGLConfig, HIROConfig, LoopConfig,
                       ScriptedMazeConfig, ScriptedOSCConfig, Settings, integer, sb3_model, validate)

__all__ = ["AGENTS", "ConfigError", "section_classes", "make_config", "resolve_hyper", "set_keys",
           "HIERARCHICAL", "SB3_SECTIONS"]

#: every agent ``hubsgo train --agent`` builds (agents/factory.py has a builder for each)
AGENTS = ("ddqn", "dqn", "hdqn", "higl", "hiro", "hubsgo", "ppo", "td3")
#: the agents that run the HRL loop (sections loop, high, low)
HIERARCHICAL = ("hubsgo", "hdqn")
#: flat baselines -> the preset section holding their Stable-Baselines3 arguments
SB3_SECTIONS = {"dqn": "dqn", "ddqn": "dqn", "ppo": "ppo", "td3": "td3"}


def make_config(section: str, cls: type[Settings], values: dict[str, Any], **derived: Any) -> Settings:
    """``cls`` from a section's settings (``derived``: values the builder sets itself, such as
    ``total_steps``); one-line :class:`ConfigError` on the first bad key."""
    return validate(section, cls, dict(values), derived=derived)


def section_classes(agent: str, family: str, low_level: str) -> dict[str, type]:
    """``{section: runtime settings class}`` of the sections ``agent`` reads (others it ignores)."""
    if agent in HIERARCHICAL:
        if family == "gym" and low_level == "scripted":
            raise ConfigError("low_level: a Gymnasium env of one's own has no scripted low level; use "
                              "--low-level learned", None, "low_level")
        low = {("minigrid", "scripted"): ScriptedMazeConfig, ("minigrid", "learned"): GoalDQNConfig,
               ("gym", "learned"): GoalDQNConfig,
               ("robosuite", "scripted"): ScriptedOSCConfig}.get((family, low_level), GoalTD3Config)
        return {"loop": LoopConfig, "high": HighLevelConfig, "low": low}
    if agent in ("hiro", "higl"):
        if family == "gym":
            raise ConfigError(f"agent {agent} sets goals in a space it knows (a maze cell, an arm's position), which a "
                              "Gymnasium env of one's own does not declare; use hubsgo, hdqn or a flat baseline",
                              None, "agent")
        return {"hiro": HIROConfig} if agent == "hiro" else {"higl": HIGLConfig}
    return {}


def _models(agent: str, family: str, low_level: str) -> dict[str, type[Settings]]:
    models = dict(section_classes(agent, family, low_level))
    if agent in SB3_SECTIONS:
        models[SB3_SECTIONS[agent]] = sb3_model(SB3_SECTIONS[agent])
    return models


def read_sections(agent: str, family: str, low_level: str) -> list[str]:
    """The settings sections ``agent`` reads, sorted."""
    return sorted(_models(agent, family, low_level))


def unread_items(agent: str, family: str, low_level: str, overrides: Sequence[str]) -> list[str]:
    """The ``--set`` items of an agent's section that ``agent`` does not read (``hiro.c`` for higl): checked,
    since a sweep gives its overrides to every agent of its grid, and then unused."""
    unread = {"loop", "high", "low", "hiro", "higl", *SB3_SECTIONS.values()} - set(read_sections(agent, family,
                                                                                                low_level))
    return [item for item in overrides
            if "." in item.partition("=")[0] and item.partition("=")[0].strip().split(".")[0] in unread]


def _other_models(family: str, low_level: str, base: dict[str, Any]) -> dict[str, type[Settings]]:
    """The models of every section in ``base``, whichever agent reads it: a ``--set`` item of a section the
    run's agent does not read is still checked (a sweep's overrides reach every agent of its grid)."""
    try:
        models = dict(section_classes("hdqn", family, low_level))
    except ConfigError:         # a family without that low level: its ``low`` section is not checked here
        models = {}
    models.update({"hiro": HIROConfig, "higl": HIGLConfig})
    for section in set(SB3_SECTIONS.values()) & set(base):
        models[section] = sb3_model(section)
    return {k: v for k, v in models.items() if k in base}


#: the run's own settings (outside every section), however they are given (``--steps``, ``--set``, a task)
RunSettings = create_model("RunSettings", __base__=Settings, steps=(integer(1), None),
                           low_level=(choice("learned", "scripted"), None))


def _check_item(item: str, base: dict[str, Any], hyper: dict[str, Any], models: dict[str, type[Settings]],
                agent: str, run_defaults: dict[str, Any], reads: bool = True) -> None:
    """Validate one ``--set`` item against the merged settings ``hyper``; its value, validated, goes back
    into ``hyper``. ``reads``: whether the agent reads the item's section. Nested keys are checked where
    they are used."""
    key, _, _ = item.partition("=")
    parts = key.strip().split(".")
    sections = sorted(k for k, v in base.items() if isinstance(v, dict))
    plain = sorted(k for k, v in base.items() if not isinstance(v, dict))
    if len(parts) == 1:
        name = parts[0]
        if name in sections:
            keys = [k for k in models[name].model_fields if k not in DERIVED] if name in models else []
            first = keys[0] if keys else "KEY"
            raise ConfigError(f"{name!r} is a section; set one of its keys, e.g. {name}.{first}=VALUE", None, name)
        if name not in plain:
            raise ConfigError(f"unknown setting {name!r}; settings: {', '.join(plain)}; sections: "
                              f"{', '.join(sections)}", None, name)
        if name in RunSettings.model_fields:
            hyper[name] = getattr(validate("", RunSettings, {name: hyper[name]}, defaults=run_defaults), name)
        return
    if len(parts) == 2 and parts[0] in models:
        section, name = parts
        # the family's value is the default named here; the agent is named where it reads the section
        parsed = validate(section, models[section], {name: hyper[section][name]}, base.get(section),
                          agent if reads else None)
        hyper[section][name] = parsed.model_dump(mode="json", include={name})[name]


def set_keys(overrides: Sequence[str], section: str) -> set[str]:
    """The keys of ``section`` that the ``--set`` items ``overrides`` name (``loop.gamma=0.9`` -> gamma)."""
    prefix = section + "."
    return {key[len(prefix):] for key in (item.partition("=")[0].strip() for item in overrides)
            if key.startswith(prefix)}


def resolve_hyper(family: str, task: str | None, agent: str, overrides: list[str] = (), *,
                  steps: int | None = None, low_level: str | None = None) -> dict[str, Any]:
    """The run's settings: the family's defaults, the task's settings, ``steps``/``low_level`` and the
    ``--set`` overrides merged, each override validated, the run's own settings checked however they
    were given, and every section ``agent`` reads checked whole. Errors are one line; those of an
    override start ``--set ITEM:``."""
    hyper = preset(family, task)
    defaults = {k: hyper[k] for k in RunSettings.model_fields if k in hyper}      # the family's, named in errors
    if steps is not None:
        hyper["steps"] = int(steps)
    default_low = hyper.get("low_level")
    if low_level is not None:
        hyper["low_level"] = low_level
    base, hyper = hyper, apply_overrides(hyper, list(overrides))
    if hyper.get("low_level") != default_low and "low" in hyper:
        # the preset's low section is the family default low level's; another low level gets only what
        # --set gives it, and the loop the family sets for it where --set does not say otherwise
        given = set_keys(overrides, "low")
        hyper["low"] = {k: v for k, v in hyper["low"].items() if k in given}
        base = {**base, "low": {k: v for k, v in base["low"].items() if k in given}}
        if steps is None and task in OTHER_LOW_STEPS and not any(o.partition("=")[0].strip() == "steps"
                                                                 for o in overrides):
            hyper["steps"] = base["steps"] = OTHER_LOW_STEPS[task]
        other = {k: v for k, v in FAMILIES[family].other_low_loop.items() if k not in set_keys(overrides, "loop")}
        if other:
            hyper["loop"] = {**hyper.get("loop", {}), **other}
            base = {**base, "loop": {**base.get("loop", {}), **other}}
    models = _models(agent, family, str(hyper.get("low_level", "learned")))
    others = {k: v for k, v in _other_models(family, str(hyper.get("low_level", "learned")), base).items()
              if k not in models}
    for item in overrides:
        section = item.partition("=")[0].strip().split(".")[0]
        try:
            if section in others:
                _check_item(item, base, hyper, others, agent, defaults, reads=False)
            else:
                _check_item(item, base, hyper, models, agent, defaults)
        except ConfigError as exc:
            raise ConfigError(f"--set {item}: {exc}", exc.section, exc.key) from None
    validate("", RunSettings, {k: hyper[k] for k in RunSettings.model_fields if k in hyper}, defaults=defaults)
    classes = section_classes(agent, family, str(hyper.get("low_level", "learned")))
    for section, cls in classes.items():
        derived = {k: int(hyper["steps"]) for k in DERIVED if k in cls.model_fields}
        try:        # the whole section: the family's keys, the task's and the overrides together
            make_config(section, cls, hyper.get(section, {}), **derived)
        except ValueError as exc:
            if not overrides:
                raise
            msg = " ".join(str(exc).split())
            raise ConfigError(f"the run cannot be built with --set {' --set '.join(overrides)}: {msg}",
                              section, "") from None
    return hyper
