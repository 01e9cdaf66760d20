"""A resolved run: :class:`RunConfig` (what the user asks for) resolved into :class:`ResolvedRun`.

:class:`ResolvedRun` is everything a run needs, typed and frozen: the task (and where its catalogue
lives), the agent, the seed, the hyperparameter sections, the critic's spec and the harness settings.
``config.yaml`` and every checkpoint hold it as plain data (:meth:`ResolvedRun.to_dict`); a run read
back is checked field by field (:meth:`ResolvedRun.from_dict`), so a damaged file is refused in one
line wherever it is loaded.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import RunError

__all__ = ["RunConfig", "ResolvedRun", "RunError", "CHECKPOINT_STEPS", "HISTORY_EVERY"]

#: env steps between checkpoints. Counted in env steps, not episodes (as Stable-Baselines3's
#: CheckpointCallback does), so that an agent whose episodes get short does not pay for more checkpoints
#: (each holds the replay buffers) than one that still wanders; a kill loses at most this many steps.
CHECKPOINT_STEPS = 5_000
#: training episodes between snapshots of the critic's marginals (critic_history.csv)
HISTORY_EVERY = 5


@dataclass
class RunConfig:
    """What a user asks for; :func:`~hubsgo_ppl.experiments.resolve.resolve` turns it into a :class:`ResolvedRun`."""

    task: str
    agent: str = "hubsgo"
    model: str | None = None          # spec name or path; default "<task>-specific"
    graph: str | None = None          # override the spec's graph preset
    steps: int | None = None          # env-step budget; default per task family
    seed: int = 0
    low_level: str | None = None      # "learned" | "scripted"; default per task family
    checkpoint_steps: int = CHECKPOINT_STEPS   # env steps between checkpoints
    history_every: int = HISTORY_EVERY         # episodes between critic marginal snapshots
    threads: int = 1                  # torch threads (small nets: 1 is fastest and reproducible)
    overrides: list[str] = field(default_factory=list)
    init_from: str | None = None      # a run directory whose critic / high level / low level start this run
    transfer: list[str] | None = None  # which of them ("critic", "high", "low"); default: all that apply
    # with init_from: start the transferred parts' schedules afresh instead of where the source left them
    restart_schedules: bool = False


def _whole(value: Any, minimum: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= minimum


@dataclass(frozen=True)
class ResolvedRun:
    """A run as it is trained, resumed, evaluated and reviewed. ``hyper`` holds the sections the agent
    is built from (``loop``, ``high``, ``low``, ``env``, the baselines' own), ``steps`` and ``low_level``."""

    task: str                          # the task's name
    task_ref: str                      # a built-in name, or a user's catalogue by its absolute path
    family: str                        # "minigrid" | "robosuite"
    agent: str
    seed: int
    hyper: Mapping[str, Any]
    checkpoint_steps: int = CHECKPOINT_STEPS
    history_every: int = HISTORY_EVERY
    threads: int = 1
    versions: Mapping[str, str] = field(default_factory=dict)
    task_digest: str | None = None     # SHA-256 of a user's catalogue and its layout
    subgoals: tuple[str, ...] | None = None   # the candidates, where the spec lists a subset of the catalogue
    model_spec: Mapping[str, Any] | None = None
    model: str | None = None
    init_from: Mapping[str, Any] | None = None
    revision: int | None = None        # the number of the last revision of the critic spec
    extra: Mapping[str, Any] = field(default_factory=dict)    # keys a later version wrote, kept as they are

    # -- the hyperparameter sections -----------------------------------------------------------------
    @property
    def steps(self) -> int:
        """The env-step budget."""
        return int(self.hyper["steps"])

    @property
    def low_level(self) -> str | None:
        return self.hyper.get("low_level")

    def section(self, name: str) -> dict[str, Any]:
        """One hyperparameter section (``loop``, ``high``, ``low``, ``env``, ...), empty where absent."""
        return dict(self.hyper.get(name) or {})

    @property
    def has_critic(self) -> bool:
        return self.agent == "hubsgo"

    def replace(self, **changes: Any) -> ResolvedRun:
        return dataclasses.replace(self, **changes)

    def with_steps(self, steps: int) -> ResolvedRun:
        return self.replace(hyper={**copy.deepcopy(dict(self.hyper)), "steps": int(steps)})

    # -- plain data ----------------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The plain data of config.yaml and checkpoints (a deep copy; optional keys only where set)."""
        d: dict[str, Any] = {"task": self.task, "task_ref": self.task_ref, "family": self.family}
        if self.task_digest is not None:
            d["task_digest"] = self.task_digest
        d.update({"agent": self.agent, "seed": self.seed, "hyper": self.hyper,
                  "checkpoint_steps": self.checkpoint_steps, "history_every": self.history_every,
                  "threads": self.threads, "versions": self.versions})
        for key in ("subgoals", "model_spec", "model", "init_from", "revision"):
            value = getattr(self, key)
            if value is not None:
                d[key] = list(value) if key == "subgoals" else value
        d.update(self.extra)
        return copy.deepcopy(_plain(d))

    @classmethod
    def from_dict(cls, data: Any, source: str = "the run's config") -> ResolvedRun:
        """Check plain data field by field; :class:`RunError` names the first bad field and ``source``."""
        def bad(what: str) -> RunError:
            return RunError(f"{source}: damaged: {what}; it was not written by `hubsgo train` as it is now; "
                            "start a new run with another --out")

        if not isinstance(data, Mapping):
            raise bad(f"a {type(data).__name__}, not a mapping of settings")
        for key in ("task", "task_ref", "family", "agent"):
            if not isinstance(data.get(key), str) or not data.get(key):
                raise bad(f"{key} is {_show(data.get(key))}, not a name")
        if not _whole(data.get("seed"), 0):
            raise bad(f"seed is {_show(data.get('seed'))}, not a whole number >= 0")
        hyper = data.get("hyper")
        if not isinstance(hyper, Mapping):
            raise bad(f"hyper is {_show(hyper)}, not a mapping of sections")
        if not _whole(hyper.get("steps"), 1):
            raise bad(f"hyper.steps is {_show(hyper.get('steps'))}, not a positive number of env steps")
        for name, section in hyper.items():
            if name not in ("steps", "low_level") and not isinstance(section, Mapping):
                raise bad(f"hyper.{name} is {_show(section)}, not a mapping")
        for key, default in (("checkpoint_steps", CHECKPOINT_STEPS), ("history_every", HISTORY_EVERY), ("threads", 1)):
            if not _whole(data.get(key, default), 1):
                raise bad(f"{key} is {_show(data.get(key))}, not a positive whole number")
        kinds = {"versions": Mapping, "task_digest": str, "subgoals": list, "model_spec": Mapping, "model": str,
                 "init_from": Mapping, "revision": int}
        for key, kind in kinds.items():
            if data.get(key) is not None and not isinstance(data[key], kind):
                raise bad(f"{key} is {_show(data[key])}")
        if data.get("subgoals") is not None and not all(isinstance(s, str) for s in data["subgoals"]):
            raise bad("subgoals is not a list of names")
        if data["agent"] == "hubsgo" and data.get("model_spec") is None:
            raise bad("agent hubsgo without a model_spec")
        known = {f.name for f in dataclasses.fields(cls)} - {"extra"}
        d = copy.deepcopy(dict(data))
        return cls(task=d["task"], task_ref=d["task_ref"], family=d["family"], agent=d["agent"], seed=d["seed"],
                   hyper=d["hyper"], checkpoint_steps=d.get("checkpoint_steps", CHECKPOINT_STEPS),
                   history_every=d.get("history_every", HISTORY_EVERY), threads=d.get("threads", 1),
                   versions=d.get("versions") or {}, task_digest=d.get("task_digest"),
                   subgoals=tuple(d["subgoals"]) if d.get("subgoals") is not None else None,
                   model_spec=d.get("model_spec"), model=d.get("model"), init_from=d.get("init_from"),
                   revision=d.get("revision"), extra={k: v for k, v in d.items() if k not in known})

    def same_run(self, other: ResolvedRun) -> bool:
        """Whether two resolved runs train the same (the package versions aside)."""
        a, b = self.to_dict(), other.to_dict()
        a.pop("versions"), b.pop("versions")
        return a == b


def as_resolved(run: ResolvedRun | Mapping[str, Any]) -> ResolvedRun:
    return run if isinstance(run, ResolvedRun) else ResolvedRun.from_dict(run)


def _plain(obj: Any) -> Any:
    """Mappings and tuples as dicts and lists (what YAML and a weights-only checkpoint hold)."""
    if isinstance(obj, Mapping):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    return obj


def _show(value: Any) -> str:
    if value is None:
        return "missing"
    text = repr(value)
    return f"the {type(value).__name__} {text[:40] + '...' if len(text) > 40 else text}"
