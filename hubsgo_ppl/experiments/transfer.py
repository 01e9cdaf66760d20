"""Carry what a run has learned over to another sub-goal set or another task, sub-goals matched by name.

Two commands use it:

- ``hubsgo revise RUN --model NEW_SPEC`` (:mod:`.revise`): the same run continues with a revised
  critic spec, so every part of the agent carries over, remapped to the new sub-goal set
  (:func:`revise_agent_state`);
- ``hubsgo train NEW_TASK --init-from RUN [--transfer critic,high,low]``: a new run starts from
  another run's critic, high level and/or low level (:func:`plan_transfer`, :func:`apply_transfer`);
  its optimisers, replay buffers and counters start afresh. Each transferred part brings its schedule
  along (:data:`SCHEDULES`, :func:`continued_schedules`): the high level's ε, the low level's ε and,
  with the critic, the probability of choosing from Ĝt start where the source run left them, so that a
  policy trained once is not made to act at random again; ``--restart-schedules`` starts them afresh.
  Every other loop setting is the run's own, as for a run from scratch.

The remapping rules are in :mod:`.remap`. A transfer (``--init-from``) takes only the networks and the critic's factors; its Ĝt is the
transferred critic's from the first episode on (not only after the first critic update, which with
an outcome likelihood waits for the first success on the new task).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import torch

from ..envs import get_task
from ..envs.subset import make_subset
from ..errors import RunError
from .io import CheckpointError, load_checkpoint
from .remap import (TransferError, name_index, remap_critic_state, remap_high_state, remap_low_state,  # noqa: F401
                    remap_rows, revise_agent_state)

__all__ = ["PARTS", "SCHEDULES", "TransferError", "TransferPlan", "name_index", "remap_rows", "remap_critic_state",
           "remap_high_state", "remap_low_state", "revise_agent_state", "plan_transfer", "apply_transfer",
           "continued_schedules", "config_subgoals"]

#: the parts of an agent ``--transfer`` names
PARTS = ("critic", "high", "low")
#: the loop's schedule (start, end, fraction keys) that each part brings along when transferred
SCHEDULES = {"critic": ("filter_start", "filter_end", "filter_fraction"),
             "high": ("explore_start", "explore_end", "explore_fraction"),
             "low": ("low_explore_start", "low_explore_end", "low_explore_fraction")}
_HIERARCHICAL = ("hubsgo", "hdqn")
#: MiniGrid observation modes whose entries name absolute cells, so that they transfer only between
#: grids of one size
_CELL_MODES = ("symbolic", "image")


@dataclass
class TransferPlan:
    source: Path
    parts: list[str]
    config: dict[str, Any]          # the source run's config
    agent: dict[str, Any]           # the source run's agent state
    env_steps: int
    names: list[str]                # the source run's candidate sub-goals
    notes: list[str] = field(default_factory=list)


def config_subgoals(config: dict[str, Any]) -> list[str]:
    """The candidate sub-goals of a run config: its ``subgoals`` subset, else its task's catalogue."""
    if config.get("subgoals"):
        return list(config["subgoals"])
    return list(get_task(config["task_ref"]).catalogue.names)


def _obs_and_actions(config: dict[str, Any]
                     ) -> tuple[tuple[int, ...], int | None, str | None, tuple[int, int] | None]:
    """The observation shape, action count, observation mode and grid size (width, height; None off
    the grid) of the env a run config builds."""
    env = make_subset(config["task_ref"], config.get("subgoals"), **config["hyper"].get("env", {}))
    try:
        n = getattr(env.action_space, "n", None)
        mode = getattr(env.unwrapped, "obs_mode", None)
        size = (int(env.unwrapped.width), int(env.unwrapped.height)) if mode in _CELL_MODES else None
        return tuple(int(d) for d in env.observation_space.shape), None if n is None else int(n), mode, size
    finally:
        env.close()


def _parse_parts(parts: Sequence[str] | str | None) -> list[str] | None:
    if parts is None:
        return None
    raw = parts.split(",") if isinstance(parts, str) else [x for p in parts for x in str(p).split(",")]
    items = [p.strip() for p in raw if p.strip()]
    bad = [p for p in items if p not in PARTS]
    if bad or not items:
        raise TransferError(f"--transfer {','.join(items) or '(empty)'}: use some of {', '.join(PARTS)}, comma-separated")
    return [p for p in PARTS if p in items]


def _learned_low(config: dict[str, Any]) -> bool:
    return config.get("agent") in _HIERARCHICAL and config["hyper"].get("low_level", "learned") == "learned"


_ELSEWHERE = "start from another run, or train without --init-from"


def _cause(exc: Exception) -> str:
    """What is wrong with a source run's checkpoint, without the advice meant for the run's own commands."""
    text = " ".join(str(exc).split())
    for advice in ("; start a new run", "; use a checkpoint", "; point at", "; train first"):
        text = text.split(advice)[0]
    return text


def _restored(path: Path, ckpt: dict[str, Any]) -> None:
    from .restore import restore

    env = restore(path, ckpt)[1]
    env.close()


def _note_other_landmarks(src_dir: Path, src: dict[str, Any], resolved: dict[str, Any], alt: str) -> None:
    """The egocentric observation has entries per catalogue sub-goal, in the catalogue's order: between
    catalogues that differ, a transferred network reads one sub-goal's entries as another's."""
    a, b = (list(get_task(c["task_ref"]).catalogue.names) for c in (src, resolved))
    if a != b:
        print(f"hubsgo: note: --init-from {src_dir}: the egocentric observation has entries per catalogue sub-goal, "
              f"and {src['task']}'s ({', '.join(a)}) are not {resolved['task']}'s ({', '.join(b)}), so networks "
              f"trained on {src['task']} read {resolved['task']}'s entries as {src['task']}'s sub-goals'; give both "
              f"catalogues the same sub-goals in the same order, or {alt}", file=sys.stderr)


def plan_transfer(resolved: dict[str, Any], source: str | Path,
                  parts: Sequence[str] | str | None = None) -> TransferPlan:
    """Check that the run ``source`` can start the run ``resolved`` describes and load what it needs.
    Refuses (TransferError, one line) a missing or foreign run, an unknown part, a part one of the two
    agents lacks, and networks that cannot carry over: other observation shapes, action counts or
    hidden sizes."""
    src_dir = Path(source)
    if not src_dir.is_dir():
        raise TransferError(f"--init-from {src_dir}: no such run directory; pass the --out folder of `hubsgo train`")
    try:
        ckpt = load_checkpoint(src_dir / "checkpoint.pt")
    except CheckpointError as exc:
        raise TransferError(f"--init-from: {_cause(exc)}; {_ELSEWHERE}") from None
    src = ckpt.get("config")
    if not isinstance(src, dict) or "agent" not in ckpt:
        raise TransferError(f"--init-from {src_dir}: not a run of `hubsgo train` (its checkpoint has no config)")
    try:    # a checkpoint its own config cannot restore is damaged: refused here, not half-way through the remap
        _restored(src_dir / "checkpoint.pt", ckpt)
    except (CheckpointError, RunError) as exc:
        raise TransferError(f"--init-from: {_cause(exc)}; {_ELSEWHERE}") from None
    wanted = _parse_parts(parts)
    why: dict[str, str] = {}
    if not (src["agent"] == "hubsgo" and resolved["agent"] == "hubsgo"):
        why["critic"] = (f"a critic needs --agent hubsgo on both sides (the source run is {src['agent']!r}, "
                         f"this one {resolved['agent']!r})")
    if not (src["agent"] in _HIERARCHICAL and resolved["agent"] in _HIERARCHICAL):
        why["high"] = (f"a high level needs hierarchical agents (hubsgo, hdqn) on both sides (the source run is "
                       f"{src['agent']!r}, this one {resolved['agent']!r})")
    # what to do where the networks cannot carry over: the critic alone, where both runs have one
    alt = ("transfer the critic alone (--transfer critic)" if "critic" not in why
           else f"train without --init-from (no critic to transfer: the runs are {src['agent']} and "
                f"{resolved['agent']})")
    if src["family"] != resolved["family"]:     # an arm's observation is no maze's: no obs_mode setting bridges them
        why.setdefault("high", f"a high level reads its task's observations, and the source run is a {src['family']} "
                               f"task, this one a {resolved['family']} task ({alt})")
    if not (_learned_low(src) and _learned_low(resolved) and src["family"] == resolved["family"]):
        why["low"] = "a low level needs a learned low level of the same kind on both sides (same task family)"
    if wanted is None and src["family"] != resolved["family"]:
        raise TransferError(f"--init-from {src_dir}: the source run is a {src['family']} task and this one a "
                            f"{resolved['family']} task, so their networks read different observations and only a "
                            f"critic could transfer; {alt}")
    chosen = wanted if wanted is not None else [p for p in PARTS if p not in why]
    refused = [p for p in chosen if p in why]
    if refused:
        raise TransferError(f"--init-from {src_dir}: cannot transfer the {refused[0]}: {why[refused[0]]}")
    if not chosen:
        raise TransferError(f"--init-from {src_dir}: nothing to transfer: {why['high']}")
    if "high" in chosen or "low" in chosen:
        src_obs, src_n, src_mode, src_size = _obs_and_actions(src)
        dst_obs, dst_n, dst_mode, dst_size = _obs_and_actions(resolved)
        if src_mode != dst_mode:
            raise TransferError(
                f"--init-from {src_dir}: observation modes differ: the source run observes {src_mode!r}, this one "
                f"{dst_mode!r}; set --set env.obs_mode={src_mode}, or {alt}")
        if src_obs != dst_obs:
            hint = (" or observe egocentrically in both runs (--set env.obs_mode=egocentric: its shape depends on "
                    "the sub-goal catalogue only, not on the grid)"
                    if src_mode != "egocentric" and src["family"] == resolved["family"] == "minigrid" else "")
            raise TransferError(
                f"--init-from {src_dir}: observation shapes differ: {src['task']} has {src_obs}, {resolved['task']} "
                f"has {dst_obs}; the high and low levels read observations, so they transfer only between "
                f"tasks with the same observation shape; {alt}{hint}")
        if src_mode in _CELL_MODES and src_size != dst_size:
            # the same length, but each entry names another cell: a 13x11 grid against an 11x13 one
            raise TransferError(
                f"--init-from {src_dir}: the grids differ in size: {src['task']} is {src_size[0]}x{src_size[1]}, "
                f"{resolved['task']} {dst_size[0]}x{dst_size[1]}; the {src_mode} observation names absolute cells, so a "
                f"network trained on one grid would misread the other; {alt} "
                f"or observe egocentrically in both runs (--set env.obs_mode=egocentric)")
        if (src_mode in _CELL_MODES and src["family"] == resolved["family"] == "minigrid"
                and src["task_ref"] != resolved["task_ref"]):
            print(f"hubsgo: note: --init-from {src_dir}: both runs observe {src_mode!r}, which names absolute cells, "
                  f"so networks trained on {src['task']} read {resolved['task']}'s cells as {src['task']}'s; where "
                  "the two layouts differ, observe egocentrically in both runs (--set env.obs_mode=egocentric), or "
                  f"{alt}", file=sys.stderr)
        if src_mode == "egocentric":
            _note_other_landmarks(src_dir, src, resolved, alt)
        if "low" in chosen and src_n != dst_n:
            rest = ",".join(p for p in chosen if p != "low")
            raise TransferError(f"--init-from {src_dir}: action counts differ: {src['task']} has {src_n} actions, "
                                f"{resolved['task']} {dst_n}; leave out the low level"
                                + (f" (--transfer {rest})" if rest else ""))
        for part in ("high", "low"):
            a = list(src["hyper"].get(part, {}).get("hidden", []))
            b = list(resolved["hyper"].get(part, {}).get("hidden", []))
            if part in chosen and a != b:
                raise TransferError(f"--init-from {src_dir}: the {part} level's hidden sizes differ: {a} in the source "
                                    f"run, {b} here; set --set {part}.hidden={a} or leave out --transfer {part}")
    names = (list(ckpt["agent"]["filter"]["critic"]["names"]) if src["agent"] == "hubsgo"
             else config_subgoals(src))
    return TransferPlan(src_dir, chosen, src, ckpt["agent"], int(ckpt.get("env_steps", 0)), names)


def continued_schedules(plan: TransferPlan, keep: Sequence[str] = ()) -> dict[str, float]:
    """``{loop key: value}``: the start of each transferred part's schedule (:data:`SCHEDULES`) set to
    the value the source run's schedule had reached at its last step; the keys in ``keep`` (those the
    user set) are left out."""
    from ..agents.config import make_config
    from ..agents.loop import LoopConfig
    from ..agents.schedules import LinearSchedule

    hyper = plan.config["hyper"]
    src = make_config("loop", LoopConfig, hyper.get("loop", {}), total_steps=int(hyper["steps"]))
    progress = plan.env_steps / max(src.total_steps, 1)
    out = {}
    for part in plan.parts:
        start, end, fraction = SCHEDULES[part]
        if start not in keep:
            value = LinearSchedule(getattr(src, start), getattr(src, end), getattr(src, fraction))(progress)
            out[start] = round(float(value), 6)
    return out


def apply_transfer(agent: Any, plan: TransferPlan) -> dict[str, Any]:
    """Load the planned parts of the source run into ``agent`` (a freshly built loop), sub-goals matched
    by name; returns what config.yaml records under ``init_from``."""
    fresh = agent.state_dict()
    new_names = list(agent.names)
    index = name_index(plan.names, new_names)
    state = dict(fresh)
    mapped: dict[str, Any] = {}
    if "critic" in plan.parts:
        critic, info = remap_critic_state(plan.agent["filter"]["critic"], agent.filter.critic, keep_run=False)
        # a transferred critic completes what the agent holds where no sample holds it (CriticFilter)
        state["filter"] = {"critic": critic, "mask": None, "outcomes": torch.zeros(0, len(new_names)),
                           "complete_missing": True}
        mapped["critic"] = {"subgoals": f"{len(info['subgoals_kept'])}/{len(new_names)}",
                            "edges": f"{len(info['edges_kept'])}/{len(info['edges_kept']) + len(info['edges_new'])}",
                            "new_subgoals": info["subgoals_new"], "new_edges": info["edges_new"]}
    kept = sum(i is not None for i in index)
    if "high" in plan.parts:
        state["high"] = remap_high_state(plan.agent["high"], fresh["high"], list(agent.high.q.parameters()),
                                         index, keep_run=False)
        mapped["high"] = {"outputs": f"{kept}/{len(new_names)}"}
    if "low" in plan.parts:
        state["low"] = remap_low_state(plan.agent["low"], fresh["low"], agent.low, index, keep_run=False)
        mapped["low"] = {"goals": f"{kept}/{len(new_names)}"}
    try:
        agent.load_state_dict(state)
    except (KeyError, RuntimeError, ValueError) as exc:
        raise TransferError(f"--init-from {plan.source}: its networks do not fit this run ({exc})") from None
    if "critic" in plan.parts:      # Ĝt from the transferred critic at once, not only after its first update
        f = agent.filter
        f.load_state_dict({**f.state_dict(), "mask": f.critic.filtered_set()})
    return {"run": str(plan.source.resolve()), "task": plan.config["task"], "agent": plan.config["agent"],
            "env_steps": plan.env_steps, "parts": list(plan.parts), "mapped": mapped}
