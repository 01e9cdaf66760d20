"""Resolving a run: the task, its catalogue, the critic's spec and the hyperparameters of a
:class:`RunConfig`, checked once, into a :class:`~hubsgo_ppl.experiments.resolved.ResolvedRun`; the notes and
warnings a user sees about what was resolved."""

from __future__ import annotations

import platform
import sys
from pathlib import Path
from typing import Any, Mapping

import torch

from .. import __version__
from ..agents.config import AGENTS, HIERARCHICAL, SB3_SECTIONS, ConfigError, read_sections, resolve_hyper, unread_items
from ..agents.presets import FAMILIES, TASK_PRESETS
from ..envs import get_task
from ..envs.subset import catalogue_order, check_subset
from .io import CheckpointError
from .resolved import ResolvedRun, RunConfig, RunError, as_resolved

#: how a run notes the budget it takes where none is given (``hubsgo tasks`` lists it as a line of its own)
BUDGET_NOTE = "hubsgo: note: no --steps: "

__all__ = ["resolve", "resolve_run", "task_ref", "catalogue_digest", "check_catalogue", "is_catalogue", "task_goals",
           "warn_goals_left_out", "note_unlinked_goals", "env_keys", "horizon_below_option"]

#: MiniGridEnv's arguments that a layout maze sets itself (its size, mission and occlusion)
_MAZE_SETS = {"self", "catalogue", "mission_space", "grid_size", "width", "height", "see_through_walls"}


def task_ref(task: str | Path) -> str:
    """How a run's config names its task: a built-in name as given, a user's catalogue by its absolute
    path, so that the run can be evaluated, reviewed, revised and resumed from any folder."""
    return str(Path(task).resolve()) if is_catalogue(task) else str(task)


def is_catalogue(task: str | Path) -> bool:
    return Path(str(task)).suffix in (".yaml", ".yml")


def catalogue_digest(path: str | Path) -> str:
    """SHA-256 of a user's catalogue and the layout file it names: a run records it, and a run read
    later says so where the files have changed since."""
    import hashlib

    import yaml

    path = Path(path)
    h = hashlib.sha256(path.read_bytes())
    try:
        options = (yaml.safe_load(path.read_text(encoding="utf-8")) or {}).get("options") or {}
    except (UnicodeDecodeError, yaml.YAMLError, AttributeError):
        return h.hexdigest()            # a damaged catalogue: its own bytes say it changed
    layout = options.get("layout") if isinstance(options, dict) else None
    if isinstance(layout, str) and (path.parent / layout).is_file():
        h.update((path.parent / layout).read_bytes())
    return h.hexdigest()


def check_catalogue(run: ResolvedRun | Mapping[str, Any]) -> bool:
    """Before a run is rebuilt: refuse (one line) a user's catalogue that has gone, and warn (and say
    True) where it has changed since the run recorded it."""
    run = as_resolved(run)
    ref = run.task_ref
    if not is_catalogue(ref):
        return False
    if not Path(ref).is_file():
        raise RunError(f"{ref}: the run's task catalogue is no longer there; put it (and its layout) back at that "
                       "path to read or resume the run")
    recorded = run.task_digest
    if recorded is not None and catalogue_digest(ref) != recorded:
        print(f"hubsgo: warning: {ref} (or its layout) has changed since the run recorded it; the run is read "
              "with the files as they are now", file=sys.stderr)
        return True
    return False


def env_keys(info: Any) -> list[str] | None:
    """The keys of section ``env`` (``--set env.KEY=VALUE``) that the env of task ``info`` takes: for a
    layout maze its own arguments and those it passes on to MiniGridEnv. None where the env passes them
    on to code of its own (a registered MiniGrid id, a Gymnasium env, a robosuite scene, which names its
    options itself when one is wrong)."""
    import inspect

    options = info.catalogue.options if isinstance(info.catalogue.options, dict) else {}
    if info.family != "minigrid" or "gym_id" in options:
        return None
    from minigrid.minigrid_env import MiniGridEnv

    from ..envs.minigrid.maze import MazeEnv

    keys = set()
    for cls in (MazeEnv, MiniGridEnv):
        keys |= {p.name for p in inspect.signature(cls.__init__).parameters.values()
                 if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)}
    return sorted(keys - _MAZE_SETS)


def _check_env_keys(cfg: RunConfig, info: Any) -> None:
    """Refuse, as an unknown key of any other section is, a ``--set env.KEY`` the task's env does not take."""
    given = [(item, item.partition("=")[0].strip()[len("env."):]) for item in cfg.overrides
             if item.partition("=")[0].strip().startswith("env.")]
    keys = env_keys(info) if given else None
    for item, name in given:
        if keys is not None and name not in keys:
            raise RunError(f"--set {item}: unknown key {name!r} in section 'env' (task {info.name}); valid keys: "
                           f"{', '.join(keys)}")


def _check_scripted_maze(agent: str, info: Any, hyper: Mapping[str, Any]) -> None:
    """Refuse, before any env is built, the scripted maze low level on a registered MiniGrid id: it plans
    on the symbolic state of an ASCII layout, which MiniGrid's own environments do not give."""
    options = info.catalogue.options if isinstance(info.catalogue.options, dict) else {}
    if agent in HIERARCHICAL and info.family == "minigrid" and hyper.get("low_level") == "scripted" \
            and "gym_id" in options:
        raise RunError(f"--low-level scripted plans on a maze's ASCII layout, and task {info.name!r} is the "
                       f"registered MiniGrid environment {options['gym_id']}; train with --low-level learned")


def _episode_budget(info: Any, hyper: Mapping[str, Any]) -> tuple[int, int] | None:
    """The budget of a run that gives none, where its family counts budgets in episodes and the task has
    no budget of its own: the family's episodes and the task's horizon (``--set env.horizon``, else the
    catalogue's, else the scene's default). None where the family's ``steps`` stand."""
    episodes = FAMILIES[info.family].episodes      # the family is known: resolve_hyper read its preset
    if episodes is None or (info.shipped and "steps" in TASK_PRESETS.get(info.name, {})):
        return None
    from ..envs.robosuite.options import DEFAULT_HORIZON

    horizon = hyper.get("env", {}).get("horizon", info.catalogue.options.get("horizon", DEFAULT_HORIZON))
    return int(episodes), int(horizon)


def horizon_below_option(run: ResolvedRun | Mapping[str, Any]) -> str | None:
    """What to say where an arm task's horizon (``--set env.horizon``, else the catalogue's, else the
    scene's default) is shorter than one option of the hierarchical agents (``loop.option_steps``, the
    control steps the low level is given for one sub-goal); None otherwise."""
    run = as_resolved(run)
    if run.family != "robosuite" or run.agent not in HIERARCHICAL:
        return None
    from ..envs.robosuite.options import DEFAULT_HORIZON

    options = get_task(run.task_ref).catalogue.options
    horizon = int(run.section("env").get("horizon", options.get("horizon", DEFAULT_HORIZON)))
    option = int(run.section("loop").get("option_steps", 0))
    if horizon >= option:
        return None
    return (f"horizon {horizon} is shorter than one option (loop.option_steps {option} control steps, what the "
            f"{run.low_level} low level is given for one sub-goal), so an episode ends before most sub-goals can be "
            f"reached and few or none succeed; raise options.horizon (or --set env.horizon) to {option} or more")


# a flat baseline's preset section -> the actions it takes (a family without the section has the other kind)
_SB3_ACTIONS = {"dqn": "discrete", "ppo": "discrete or continuous", "td3": "continuous"}


def _check_agent_family(agent: str, family: str) -> None:
    """Refuse, before any env is built, a flat baseline the task's family has no settings for: one that
    takes the other kind of actions (td3 on a maze, dqn or ddqn on an arm)."""
    section = SB3_SECTIONS.get(agent)
    sb3 = FAMILIES[family].sb3
    if section is None or section in sb3:
        return
    fits = [a for a in AGENTS if SB3_SECTIONS.get(a) in sb3 or (a not in SB3_SECTIONS and
                                                                 not (family == "gym" and a in ("hiro", "higl")))]
    raise RunError(f"agent {agent!r} takes {_SB3_ACTIONS.get(section, 'other')} actions and does not train on "
                   f"{family} tasks; use one of: {', '.join(fits)}")


def _set_items(overrides: list[str], key: str) -> list[str]:
    """The ``--set`` items that set the run's own setting ``key`` (``steps``, ``low_level``)."""
    return [o for o in overrides if o.split("=", 1)[0].strip() == key]


def resolve(cfg: RunConfig) -> dict[str, Any]:
    """Everything a run needs, as plain data (written to config.yaml and into checkpoints)."""
    return resolve_run(cfg).to_dict()


def resolve_run(cfg: RunConfig) -> ResolvedRun:
    """Everything a run needs, typed (:class:`ResolvedRun`)."""
    if not isinstance(cfg.task, (str, Path)) or not str(cfg.task):
        raise RunError(f"task must be a task name or the path of a catalogue, got {cfg.task!r}")
    if isinstance(cfg.overrides, (str, bytes)) or not all(isinstance(o, str) for o in cfg.overrides):
        raise RunError(f"overrides must be a list of 'KEY=VALUE' strings, e.g. ['loop.option_steps=30'], got "
                       f"{cfg.overrides!r}")
    info = get_task(cfg.task)
    if int(cfg.checkpoint_steps) <= 0:
        raise RunError(f"checkpoint_steps must be a positive number of env steps, got {cfg.checkpoint_steps}")
    for name in ("history_every", "threads"):
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise RunError(f"{name} must be a positive whole number, got {value!r}")
    if isinstance(cfg.seed, bool) or not isinstance(cfg.seed, int) or cfg.seed < 0:
        raise RunError(f"a seed is a whole number, 0 or more; got {cfg.seed!r}")
    if cfg.agent not in AGENTS:
        raise RunError(f"unknown agent {cfg.agent!r}; use one of: {', '.join(AGENTS)}")
    _check_agent_family(cfg.agent, info.family)
    if (cfg.transfer is not None or cfg.restart_schedules) and cfg.init_from is None:
        what = "transfer names what to take" if cfg.transfer is not None else "restart_schedules is about what is taken"
        raise RunError(f"{what} from the run given by init_from; give init_from=RUN (--init-from RUN)")
    low_set = _set_items(cfg.overrides, "low_level")
    if (cfg.low_level is not None or low_set) and cfg.agent not in HIERARCHICAL:
        given = f"--low-level {cfg.low_level}" if cfg.low_level is not None else f"--set {low_set[-1]}"
        own = "its own goal-conditioned low level" if cfg.agent in ("hiro", "higl") else "no low level"
        raise RunError(f"{given} picks the low level of hubsgo and hdqn, and agent {cfg.agent!r} has {own}; "
                       "drop it")
    budget_set = _set_items(cfg.overrides, "steps")
    if cfg.steps is not None and budget_set:
        raise RunError(f"the budget is given twice, --steps {cfg.steps} and --set {budget_set[-1]}; give it once")
    try:        # the preset, the task's settings and --set merged and validated (agents/config.py)
        preset_task = info.name if info.shipped else None      # a user's catalogue: the family's defaults
        hyper = resolve_hyper(info.family, preset_task, cfg.agent, cfg.overrides, steps=cfg.steps,
                              low_level=cfg.low_level)
        episodes = _episode_budget(info, hyper) if cfg.steps is None and not budget_set else None
        if episodes is not None:
            count, horizon = episodes
            hyper = resolve_hyper(info.family, preset_task, cfg.agent, cfg.overrides, steps=count * horizon,
                                  low_level=cfg.low_level)
            print(f"{BUDGET_NOTE}{count * horizon:,} env steps, the {info.family} family's {count} "
                  f"episodes of the task's {horizon}-step horizon", file=sys.stderr)
    except ValueError as exc:           # a ConfigError always; another ValueError where --set caused it
        if not (cfg.overrides or isinstance(exc, ConfigError)):
            raise
        raise RunError(str(exc)) from None
    _check_env_keys(cfg, info)
    _check_scripted_maze(cfg.agent, info, hyper)
    low = str(hyper.get("low_level", "learned"))
    unread = unread_items(cfg.agent, info.family, low, cfg.overrides)
    if unread:
        reads = read_sections(cfg.agent, info.family, low)
        print(f"hubsgo: note: --set {', '.join(unread)}: agent {cfg.agent!r} reads none of it (its sections: "
              f"{', '.join(reads) or 'none'}); checked, then unused", file=sys.stderr)
    ref = task_ref(cfg.task)
    resolved: dict[str, Any] = {
        "task": info.name, "task_ref": ref, "family": info.family,
        **({"task_digest": catalogue_digest(ref)} if is_catalogue(cfg.task) else {}),
        "agent": cfg.agent, "seed": int(cfg.seed), "hyper": hyper,
        "checkpoint_steps": int(cfg.checkpoint_steps), "history_every": cfg.history_every, "threads": cfg.threads,
        "versions": {"hubsgo_ppl": __version__, "torch": str(torch.__version__), "python": platform.python_version()},
    }
    names = info.catalogue.names
    if cfg.graph is not None and cfg.agent != "hubsgo":
        raise RunError(f"--graph {cfg.graph} sets the critic's graph, and agent {cfg.agent!r} has no critic; "
                       "drop --graph, or train --agent hubsgo")
    if cfg.model is not None and cfg.agent not in HIERARCHICAL:
        raise RunError(f"--model {cfg.model} sets the critic spec and the candidate sub-goals, and agent {cfg.agent!r} "
                       "chooses from no sub-goal catalogue; drop --model, or train --agent hubsgo or hdqn")
    if cfg.agent == "hubsgo" or cfg.model is not None:
        from ..specs import ModelSpec, SpecError, for_family, list_model_specs, load_model_spec, match_subgoals

        model = cfg.model or f"{info.name}-specific"
        missing = cfg.model is None and model not in list_model_specs()
        inherited = None
        if missing and cfg.init_from is not None:
            inherited = _source_spec(cfg.init_from)     # a user's maze started from another run: that run's spec
        edgeless = missing and inherited is None and cfg.graph in ("independent", "fully_connected")
        if missing and inherited is None and not edgeless and cfg.init_from is not None:
            raise SpecError(f"task {info.name!r} has no built-in critic spec {model}, and the --init-from run "
                            f"{cfg.init_from} trained no critic to take one from: pass --model my_spec.yaml, or "
                            "train with --graph independent, which needs no edges")
        if missing and inherited is None and not edgeless:
            raise SpecError(f"task {info.name!r} has no built-in critic spec {model}: write one (its sub-goals, "
                            "your signed edges, the prior and the likelihood; models/keydoor-specific.yaml is an "
                            "example) and pass it with --model my_spec.yaml, or train with --graph independent, "
                            "which needs no edges")
        if inherited is not None:
            spec = inherited if cfg.graph is None else inherited.model_copy(update={"graph": cfg.graph})
            model = spec.name
            print(f"hubsgo: note: no --model: the critic spec of the --init-from run, {spec.name!r}", file=sys.stderr)
        elif edgeless:      # a graph that takes no human edges: the default prior and likelihood over the catalogue
            spec = ModelSpec(name=f"{info.name}-{cfg.graph}", task=info.name, subgoals=list(names), graph=cfg.graph)
            model = spec.name
            print(f"hubsgo: note: no --model: graph {cfg.graph} over the catalogue's {len(names)} sub-goals, with "
                  "the default prior and likelihood; a spec with your signed edges (--model) adds what you know",
                  file=sys.stderr)
        else:
            spec = load_model_spec(model, graph=cfg.graph)
        spec = for_family(spec, info.family)        # a likelihood left out: the family's own
        source = f"model spec {model!r} for task {info.name!r}"
        if set(spec.subgoals) >= set(names):
            spec = match_subgoals(spec, list(names), source)
        else:       # some of the catalogue's sub-goals: the run's candidates are those (envs/subset.py)
            check_subset(spec.subgoals, names, source)
            spec = spec.model_copy(update={"subgoals": catalogue_order(spec.subgoals, names)})
            resolved["subgoals"] = list(spec.subgoals)
        resolved["model_spec"] = spec.model_dump(mode="json")
        resolved["model"] = spec.name
        if cfg.model is None and inherited is None and not edgeless and is_catalogue(cfg.task):
            print(f"hubsgo: note: no --model: the built-in spec {model!r}, named after the catalogue's task "
                  f"{info.name!r}; pass --model to use your own", file=sys.stderr)
        if spec.task is not None and spec.task != info.name:     # it fits (above); say whose it was
            print(f"hubsgo: note: model spec {spec.name!r} names task {spec.task!r}; it is used for {info.name!r}, "
                  "its sub-goals matched by name", file=sys.stderr)
        if cfg.graph is None and spec.graph == "independent" and spec.edges:
            print(f"hubsgo: note: model spec {spec.name!r} has graph independent, so its edges ({len(spec.edges)}) "
                  "are not used; graph specific uses them", file=sys.stderr)
    return ResolvedRun.from_dict(resolved, "the resolved run")


def _source_spec(run_dir: str | Path) -> Any:
    """The critic spec a run was trained with, or None where it has none."""
    from ..specs import ModelSpec, validate_spec

    from .checkpoint import run_config

    try:
        spec = run_config(run_dir).get("model_spec")
    except (RunError, CheckpointError) as exc:     # no run there, or a damaged one: that, not a missing spec
        raise RunError(f"--init-from {run_dir}: {str(exc).removeprefix(f'{run_dir}: ')}") from None
    if not isinstance(spec, dict):
        return None
    return validate_spec(ModelSpec, spec, source=f"--init-from {run_dir}: its critic spec")


def task_goals(task_ref: str) -> list[str]:
    """The names of the task catalogue's ``goal`` sub-goals."""
    return [d.name for d in get_task(task_ref).catalogue.subgoals if d.kind == "goal"]


def warn_goals_left_out(spec_name: str, task_ref: str, subgoals: list[str] | None) -> None:
    """One warning line when a run's candidate set (a spec's ``subgoals``; None: the whole catalogue)
    leaves out the task's goal: the high level can never choose it, so the agent reaches it only by chance."""
    missing = [g for g in task_goals(task_ref) if g not in subgoals] if subgoals else []
    if missing:
        print(f"hubsgo: warning: model spec {spec_name!r} leaves out {', '.join(missing)} (the task's goal): the high "
              "level can never choose it, so the agent reaches it only by chance; add it to subgoals and link the "
              "last sub-goal of each route to it", file=sys.stderr)


def _unlinked_goals(run: ResolvedRun) -> list[str]:
    """The catalogue's ``goal`` sub-goals that a ``specific`` spec links to nothing by a positive edge,
    where its Ising prior's negative field outweighs what the outcome likelihood makes of a sub-goal
    every success achieves (``OutcomeLikelihood.mismatch_nats``): G* then leaves them out
    (docs/results.md, "How strongly the successes speak")."""
    from ..infer.likelihoods import get_likelihood

    spec = run.model_spec
    prior, lik = ((spec or {}).get(k) or {} for k in ("prior", "likelihood"))
    if not spec or spec.get("graph") != "specific" or prior.get("name") != "ising" or lik.get("name") != "outcome":
        return []
    outcome = get_likelihood("outcome", **{k: v for k, v in lik.items() if k != "name"})
    if outcome.mismatch_nats > -float(prior.get("field", 0.0)):
        return []
    linked = {end for u, v, sign in spec.get("edges", []) if sign == "positive" for end in (u, v)}
    return [g for g in task_goals(run.task_ref) if g in spec["subgoals"] and g not in linked]


def note_unlinked_goals(run: ResolvedRun | Mapping[str, Any]) -> None:
    """A one-line note on stderr for each run (new or revised) whose spec leaves the goal unlinked."""
    run = as_resolved(run)
    unlinked = _unlinked_goals(run)
    if unlinked:
        print(f"hubsgo: note: model spec {run.model!r} gives {', '.join(unlinked)} (the task's goal) no "
              "positive edge, so its prior's field keeps it out of G*; link the last sub-goal of each route "
              "to it (e.g. [a_door, goal, positive])", file=sys.stderr)
