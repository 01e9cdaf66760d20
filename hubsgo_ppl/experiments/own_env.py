"""Training on a Gymnasium environment of one's own from Python (docs/own_env.md).

:func:`train_env` writes the env and its named sub-goals as a catalogue of family ``gym``
(``envs/gym_task.py``) into the run folder (``task.yaml``, and the critic spec as ``spec.yaml`` when it
is given as an object), then trains through :func:`~hubsgo_ppl.experiments.driver.train`, so the folder
is a run like any other: ``hubsgo subgoals``, ``evaluate``, ``review``, ``revise``, ``diagnose``,
``render`` and ``train RUN/task.yaml --out RUN --resume`` read it::

    from hubsgo_ppl.experiments import train_env
    train_env("my_pkg.envs:make_env", {"has_key": has_key, "goal": {"kind": "goal"}},
              model="my_spec.yaml", out="runs/mine", steps=20_000)
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import yaml

from ..envs.gym_task import KINDS, callable_ref
from ..specs import ModelSpec, SpecError, validate_spec
from .callbacks import Callback
from .checkpoint import CHECKPOINT
from .driver import train
from .io import write_text
from .resolved import RunConfig, RunError

__all__ = ["train_env", "env_catalogue", "TASK_FILE", "SPEC_FILE"]

#: the catalogue and the critic spec train_env writes into the run folder
TASK_FILE = "task.yaml"
SPEC_FILE = "spec.yaml"


def _ref(fn: Any, what: str, local: list[str]) -> str:
    """A callable (or its "module:function" name) as a catalogue names it; ``local`` collects the names
    of those no other process can import."""
    if isinstance(fn, str):
        return fn
    try:
        ref, importable = callable_ref(fn)
    except TypeError:
        raise SpecError(f"{what}: {fn!r} is neither a function nor a 'module:function' name") from None
    if not importable:
        local.append(f"{what} ({ref})")
    return ref


def _subgoal(name: str, value: Any, local: list[str]) -> dict[str, Any]:
    """One catalogue entry from a sub-goal as :func:`train_env` takes it."""
    if callable(value) or isinstance(value, str):
        return {"name": name, "kind": "predicate", "args": {"fn": _ref(value, f"sub-goal {name!r}", local)}}
    if not isinstance(value, Mapping):
        raise SpecError(f"sub-goal {name!r}: {type(value).__name__} is none of: a predicate fn(env, obs, info), "
                        "its 'module:function' name, a mapping {fn: ..., ARG: ...} or {kind: info, key: ...} "
                        "or {kind: goal}")
    args = dict(value)
    kind = args.pop("kind", "predicate")
    if kind not in KINDS:
        raise SpecError(f"sub-goal {name!r}: unknown kind {kind!r}; use one of: {', '.join(KINDS)}")
    if kind == "predicate" and "fn" in args:
        args["fn"] = _ref(args["fn"], f"sub-goal {name!r}", local)
    return {"name": name, "kind": kind, "args": args}


def env_catalogue(env: str | Callable[..., Any], subgoals: Mapping[str, Any], task: str | None = None,
                  env_kwargs: Mapping[str, Any] | None = None, max_episode_steps: int | None = None,
                  ) -> tuple[dict[str, Any], list[str]]:
    """(the catalogue of family ``gym`` as plain data, the callables in it that no other process can
    import). ``env``: a registered Gymnasium id, an env factory, or its "module:function" name."""
    local: list[str] = []
    if callable(env) or (isinstance(env, str) and ":" in env and not re.search(r"-v\d+$", env)):
        options: dict[str, Any] = {"entry_point": _ref(env, "env", local)}
    elif isinstance(env, str):
        options = {"gym_id": env}
    else:
        raise SpecError(f"env: {type(env).__name__} is neither a registered Gymnasium id, an env factory nor its "
                        "'module:function' name")
    if env_kwargs:
        options["kwargs"] = dict(env_kwargs)
    if max_episode_steps is not None:
        options["max_episode_steps"] = max_episode_steps
    if not isinstance(subgoals, Mapping) or not subgoals:
        raise SpecError("subgoals: give a mapping {name: predicate, ...} with at least one sub-goal")
    if task is None:
        source = options.get("gym_id") or options["entry_point"].split(":")[-1]
        task = "".join(c if c.isalnum() or c in "_-" else "_" for c in source.split("#")[0]).strip("_") or "own_env"
    cat = {"task": task, "family": "gym", "options": options,
           "subgoals": [_subgoal(str(name), value, local) for name, value in subgoals.items()]}
    return cat, local


def _write_once(path: Path, text: str, started: bool) -> None:
    """Write ``path``, unless it holds other text for a run already started there (refused)."""
    if path.is_file() and path.read_text(encoding="utf-8") == text:
        return
    if started and path.exists():
        raise RunError(f"{path}: the run in {path.parent} was trained with another {path.name}; choose another "
                       "out folder for a new run (its files are left as they are)")
    write_text(path, text)


def train_env(env: str | Callable[..., Any], subgoals: Mapping[str, Any], out: str | Path, *,
              model: str | Path | ModelSpec | Mapping[str, Any] | None = None, agent: str = "hubsgo",
              steps: int | None = None, seed: int = 0, task: str | None = None,
              env_kwargs: Mapping[str, Any] | None = None, max_episode_steps: int | None = None,
              overrides: Sequence[str] = (), resume: bool = False, progress: bool = False,
              stop_at: int | None = None, callbacks: Sequence[Callback] = ()) -> dict[str, Any]:
    """Train ``agent`` (``hubsgo``, ``hdqn``, or a flat baseline ``dqn``, ``ddqn``, ``ppo``) on a
    Gymnasium env of one's own into the run folder ``out``; returns :func:`train`'s summary.

    ``env``: a registered id (``"CartPole-v1"``, ``"my_pkg:MyEnv-v0"``), an env factory, or its
    ``"module:function"`` name; ``env_kwargs`` its keyword arguments (plain data), ``max_episode_steps``
    a time limit where it has none. ``subgoals``: ``{name: value}`` in the catalogue's order, each a
    predicate ``fn(env, obs, info) -> bool`` (``env`` unwrapped, ``obs`` as the env returns it), its
    "module:function" name, ``{"fn": fn, ARG: value, ...}`` (passed as ``fn(env, obs, info, ARG=value)``),
    ``{"kind": "info", "key": KEY}`` (the env's own ``info[KEY]``) or ``{"kind": "goal"}`` (the task
    solved: ``info["is_success"]`` where the env reports it, else a step that terminates with a positive
    reward). ``model``: the critic spec (a built-in name, a YAML path, a :class:`ModelSpec` or its
    mapping); HUBS-GO needs one. ``overrides``: ``--set`` items, e.g. ``["loop.option_steps=20"]``.

    Callables that no other process can import (a lambda, a nested function, a function of the running
    script) train, but the ``hubsgo`` commands cannot rebuild the run's env: one line on stderr says so.
    """
    out = Path(out)
    if agent == "hubsgo" and model is None:
        raise RunError("agent 'hubsgo' needs model=: a critic spec (a YAML path, a ModelSpec or its mapping) naming "
                       f"the sub-goals {', '.join(map(str, subgoals)) if isinstance(subgoals, Mapping) else ''}"
                       .rstrip() + " and your signed edges")
    cat, local = env_catalogue(env, subgoals, task, env_kwargs, max_episode_steps)
    # validated as `hubsgo` will read it back, before anything is written
    from ..envs.subgoals import Catalogue

    validate_spec(Catalogue, cat, source="train_env")
    started = (out / CHECKPOINT).exists() or (out / "config.yaml").exists()
    out.mkdir(parents=True, exist_ok=True)
    spec_ref: str | None = None
    if isinstance(model, (ModelSpec, Mapping)):
        spec = model if isinstance(model, ModelSpec) else validate_spec(ModelSpec, dict(model), source="model")
        spec_text = yaml.safe_dump(spec.model_dump(mode="json"), sort_keys=False, default_flow_style=None)
        _write_once(out / SPEC_FILE, spec_text, started)
        spec_ref = str((out / SPEC_FILE).resolve())
    elif model is not None:
        spec_ref = str(Path(model).resolve()) if Path(str(model)).suffix in (".yaml", ".yml") else str(model)
    _write_once(out / TASK_FILE, yaml.safe_dump(cat, sort_keys=False, default_flow_style=None), started)
    if local:
        print(f"hubsgo: note: {', '.join(local)} cannot be imported by another process, so the `hubsgo` commands "
              f"cannot rebuild {out}'s env; define them at the top level of an importable module to use them",
              file=sys.stderr)
    cfg = RunConfig(task=str((out / TASK_FILE).resolve()), agent=agent, model=spec_ref, steps=steps, seed=seed,
                    overrides=list(overrides))
    return train(cfg, out, resume=resume, progress=progress, stop_at=stop_at, callbacks=callbacks)
