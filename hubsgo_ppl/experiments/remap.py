"""Remap what a run has learned onto another sub-goal set, sub-goals matched by name: the state of the
critic, the high level and the low level (used by ``hubsgo revise`` and ``hubsgo train --init-from``,
:mod:`.revise` and :mod:`.transfer`).
Remapping rules (a sub-goal *persists* when both sides name it; an edge when both sides join the
same unordered pair of names):

- critic: the unary factor ``theta`` of every persisting sub-goal and the coupling of every
  persisting edge are copied bit for bit, whatever the edge's sign is now (a sign seeds initial
  values only; a prior built from the signs changes with them). A critic that has never updated has
  learned nothing: its factors are its starting values, so every factor starts as a fresh critic of
  the new spec starts it (a re-signed edge from its new sign). A new sub-goal's theta starts where
  the prior puts it: the prior's natural parameter when the prior is a pairwise MRF on the graph
  (``bernoulli``: logit p, ``ising``: its field), else 0. A new edge starts as a fresh critic of the
  new spec starts it: the prior's coupling with ``inference.init: prior``, else ``init_scale`` times
  its sign. The critic's Adam state and its decaying-average baseline restart when the revision
  changes the critic's objective (any of its sub-goals, edges, signs, graph, prior, likelihood or
  inference settings), and carry over when it does not; the MH chains keep their persisting columns
  and start new ones from the new critic's seeded random bits.
- high level, a Q network with one output per sub-goal: the hidden layers are copied, and of the last
  layer the row (weights and bias) of every persisting sub-goal, in the online and the target
  network. A new sub-goal's row is the mean of the rows carried over (of all the old rows when none
  is), so a greedy high level starts it at the value of an average known sub-goal, neither preferred
  nor avoided. Dropped rows go.
- low level (GoalDQN, one block of ``n_actions`` outputs per sub-goal): the same, block by block.
  GoalTD3 and the scripted controller have no per-sub-goal outputs and carry over whole.

When a revision keeps the run (:func:`revise_agent_state`), the rest carries over too: the high
level's Adam moments (rows remapped like the weights), its replay (transitions towards a dropped
sub-goal removed, goal indices remapped, a new sub-goal unavailable at every stored s' since it was
not tracked there), the low level's replay (a new sub-goal's flags set to "already achieved", which
masks it out of the stored transitions' loss; its goal weights, ``loop.low_goal_weight``, restart
with the critic's optimiser and carry over with it), the RNG streams, the counters and so the ε schedules. The filter's outcome window keeps its columns when sub-goals
are only dropped; when sub-goals are added it restarts, since the stored episodes do not say whether
they achieved the new ones. The filter's current Ĝt keeps its persisting entries and includes the new
sub-goals until the critic's next update. The critic minibatches waiting for a pooled update are
discarded when the sub-goal set changes (their columns belong to the old set).
"""

from __future__ import annotations

import copy
from collections import OrderedDict
from typing import Any, Sequence

import numpy as np
import torch

__all__ = ["TransferError", "name_index", "remap_rows", "remap_net", "remap_critic_state", "remap_high_state",
           "remap_low_state", "revise_agent_state"]


class TransferError(RuntimeError):
    """A transfer or a revision cannot be made; the message names the cause (one line)."""


# -- index maps and rows ------------------------------------------------------------------------------


def name_index(old: Sequence[str], new: Sequence[str]) -> list[int | None]:
    """For each name of ``new``, its position in ``old`` (None: a new name)."""
    pos = {n: i for i, n in enumerate(old)}
    return [pos.get(n) for n in new]


def remap_rows(old: torch.Tensor, fresh: torch.Tensor, index: Sequence[int | None], block: int = 1) -> torch.Tensor:
    """``fresh`` (rows ``len(index) * block``) with block ``j`` copied from ``old``'s block ``index[j]``;
    a new block (``index[j]`` None) is the mean of the blocks carried over (of all old blocks when none is)."""
    out = fresh.detach().clone()
    old = old.detach()
    n_old = old.shape[0] // block
    blocks = old.reshape(n_old, block, *old.shape[1:])
    kept = [i for i in index if i is not None]
    mean = blocks[kept if kept else list(range(n_old))].mean(0) if n_old else None
    for j, i in enumerate(index):
        if i is not None:
            out[j * block:(j + 1) * block] = blocks[i]
        elif mean is not None:
            out[j * block:(j + 1) * block] = mean
    return out


def _last_layer(state: dict[str, torch.Tensor]) -> tuple[str, str]:
    """The keys of the last Linear layer (weight, bias) of an ``nn.Sequential`` MLP's state dict."""
    last = max(int(k.split(".")[0]) for k in state if k.endswith(".weight"))
    return f"{last}.weight", f"{last}.bias"


def remap_net(old: dict[str, torch.Tensor], fresh: dict[str, torch.Tensor], index: Sequence[int | None],
              block: int, what: str) -> "OrderedDict[str, torch.Tensor]":
    """Hidden layers from ``old``; the last layer's rows remapped (:func:`remap_rows`)."""
    w, b = _last_layer(fresh)
    out: OrderedDict[str, torch.Tensor] = OrderedDict()
    for k, v in fresh.items():
        if k not in old:
            raise TransferError(f"{what}: the source network has no layer {k!r}; the two networks differ in depth")
        if k in (w, b):
            if tuple(old[k].shape[1:]) != tuple(v.shape[1:]):
                raise TransferError(f"{what}: last layer of shape {tuple(old[k].shape)} in the source, "
                                    f"{tuple(v.shape)} here; the hidden sizes differ")
            out[k] = remap_rows(old[k], v, index, block)
        elif tuple(old[k].shape) != tuple(v.shape):
            raise TransferError(f"{what}: layer {k} has shape {tuple(old[k].shape)} in the source and "
                                f"{tuple(v.shape)} here; the hidden sizes or the observation sizes differ")
        else:
            out[k] = old[k].detach().clone()
    return out


def _remap_adam(old: dict[str, Any], fresh_params: Sequence[torch.Tensor], index: Sequence[int | None],
                block: int) -> dict[str, Any]:
    """An Adam state dict whose moments of the last layer (the last two parameters) are remapped like
    its rows; the other parameters' state is kept."""
    opt = copy.deepcopy(old)
    ids = opt["param_groups"][0]["params"]
    for pid, param in zip(ids[-2:], fresh_params[-2:]):
        st = opt["state"].get(pid)
        if not st:
            continue
        for key in ("exp_avg", "exp_avg_sq"):
            if key in st:
                st[key] = remap_rows(st[key], torch.zeros_like(param), index, block)
    return opt


def _remap_columns(arr: np.ndarray, index: Sequence[int | None], fill: bool) -> np.ndarray:
    out = np.full((arr.shape[0], len(index)), fill, dtype=arr.dtype)
    for j, i in enumerate(index):
        if i is not None:
            out[:, j] = arr[:, i]
    return out


def _full(buf: dict[str, Any]) -> dict[str, Any]:
    """A copy of a replay buffer's state with every field at its full capacity (rows past ``size`` zero)."""
    capacity = int(buf.get("capacity", len(next(iter(buf["data"].values())))))
    data = {}
    for k, v in buf["data"].items():
        data[k] = np.zeros((capacity, *v.shape[1:]), dtype=v.dtype)
        data[k][: len(v)] = v
    return {**copy.deepcopy({k: v for k, v in buf.items() if k != "data"}), "data": data, "capacity": capacity}


def _chronological(buf: dict[str, Any]) -> np.ndarray:
    """Row positions of a ring buffer's contents, oldest first."""
    size, pos = int(buf["size"]), int(buf["pos"])
    capacity = int(buf.get("capacity", len(next(iter(buf["data"].values())))))
    if size < capacity:
        return np.arange(size)
    return np.concatenate([np.arange(pos, capacity), np.arange(pos)])


# -- the critic ---------------------------------------------------------------------------------------


def remap_critic_state(old: dict[str, Any], fresh_critic: Any, keep_run: bool = True) -> tuple[dict[str, Any], dict]:
    """The state of ``fresh_critic`` (built from the new spec) with ``old``'s factors of persisting
    sub-goals and edges (module docstring). ``keep_run``: the same run continues (RNG stream and update
    count carried over); otherwise a new run starts from the factors. Returns (state, what was kept)."""
    fresh = fresh_critic.state_dict()
    old_names, new_names = list(old["names"]), list(fresh["names"])
    index = name_index(old_names, new_names)
    natural = fresh_critic.prior.natural_params()
    theta0 = natural[0].float() if natural is not None else torch.zeros(len(new_names))
    learned = int(old.get("num_updates", 1)) > 0    # a critic never updated holds its starting values only
    theta = fresh["theta"].clone()
    for j, i in enumerate(index):
        theta[j] = old["theta"][i] if i is not None and learned else theta0[j]
    old_edges = {frozenset((u, v)): (k, int(s)) for k, (u, v, s) in enumerate(old["edges"])}
    coupling = fresh["coupling"].clone()
    kept_edges, new_edges, resigned = [], [], []
    for k, (u, v, s) in enumerate(fresh["edges"]):
        hit = old_edges.get(frozenset((u, v)))
        if hit is None:
            new_edges.append(f"{u}--{v}")
            continue
        if hit[1] != int(s):
            resigned.append(f"{u}--{v}")
        if not learned:             # the fresh critic's start, under the new sign and prior
            new_edges.append(f"{u}--{v}")
            continue
        coupling[k] = old["coupling"][hit[0]]
        kept_edges.append(f"{u}--{v}")
    ends = {frozenset((u, v)) for u, v, _ in fresh["edges"]}
    dropped_edges = [f"{u}--{v}" for u, v, _ in old["edges"] if frozenset((u, v)) not in ends]

    state = dict(fresh)
    state["theta"], state["coupling"] = theta, coupling
    same_q = old_names == new_names and not (new_edges or dropped_edges or resigned)
    for key in ("chains", "last_samples"):
        src, dst = old.get(key), fresh.get(key)
        # the last update's samples stand for q (its marginals above exact_max_n); a changed q has none yet
        if key == "last_samples" and (not keep_run or src is None or not same_q):
            state[key] = None
            continue
        base = dst if dst is not None else fresh["chains"]
        if src is None or src.shape[0] != base.shape[0]:     # a new number of samples: fresh chains
            state[key] = None if key == "last_samples" else base.clone()
            continue
        out = base.clone()
        for j, i in enumerate(index):
            if i is not None:
                out[:, j] = src[:, i]
        state[key] = out
    state["baseline"] = {}
    if keep_run:
        state["rng"], state["num_updates"] = old["rng"], int(old["num_updates"])
    info = {"subgoals_kept": [n for n, i in zip(new_names, index) if i is not None and learned],
            "subgoals_new": [n for n, i in zip(new_names, index) if i is None or not learned],
            "subgoals_dropped": [n for n in old_names if n not in new_names],
            "edges_kept": kept_edges, "edges_new": new_edges, "edges_dropped": dropped_edges,
            "edges_resigned": resigned, "learned": learned}
    return state, info


# -- the high and the low level -----------------------------------------------------------------------


def remap_high_state(old: dict[str, Any], fresh: dict[str, Any], fresh_params: Sequence[torch.Tensor],
                     index: Sequence[int | None], keep_run: bool = True) -> dict[str, Any]:
    """A :class:`~hubsgo_ppl.agents.high_level.HighLevelDQN` state for the new sub-goal set ``index``
    (module docstring). ``keep_run`` False: only the networks (a new run)."""
    out = dict(fresh)
    out["q"] = remap_net(old["q"], fresh["q"], index, 1, "high level")
    out["q_target"] = remap_net(old["q_target"], fresh["q_target"], index, 1, "high level (target)")
    if not keep_run:
        return out
    out["opt"] = _remap_adam(old["opt"], fresh_params, index, 1)
    out["updates"] = int(old["updates"])
    buf, new_buf = old["buffer"], _full(fresh["buffer"])
    goal_map = {i: j for j, i in enumerate(index) if i is not None}
    rows = _chronological(buf)
    kept = np.array([int(g) in goal_map for g in buf["data"]["goal"][rows]], dtype=bool)
    if kept.all():              # nothing dropped: every row stays where it is
        sel, positions, pos, size = rows, rows, int(buf["pos"]), int(buf["size"])
    else:                       # transitions towards a dropped sub-goal go; the rest, oldest first
        sel = rows[kept]
        positions = np.arange(len(sel))
        size = len(sel)
        pos = size % new_buf["capacity"]
    for k, arr in buf["data"].items():
        if k == "available":
            vals = _remap_columns(arr[sel], index, False)
            vals[~vals.any(1)] = True       # the loop's rule: with nothing left to achieve, all are available
        elif k == "goal":
            vals = np.array([goal_map[int(g)] for g in arr[sel]], dtype=arr.dtype)
        else:
            vals = arr[sel]
        new_buf["data"][k][positions] = vals
    new_buf["pos"], new_buf["size"] = pos, size
    out["buffer"] = new_buf
    return out


def _is_goal_dqn(state: dict[str, Any]) -> bool:
    return isinstance(state, dict) and "buffer" in state and "before" in state["buffer"].get("data", {})


def remap_low_state(old: dict[str, Any], fresh: dict[str, Any], low: Any, index: Sequence[int | None],
                    keep_run: bool = True) -> dict[str, Any]:
    """A low level's state for the new sub-goal set (GoalDQN remapped block by block; the others, which
    have no per-sub-goal outputs, whole). ``keep_run`` False: only the networks (a new run)."""
    if not _is_goal_dqn(fresh):
        if keep_run:
            return old
        out = dict(fresh)
        for key in ("actor", "actor_target", "critics", "critics_target", "norm"):    # GoalTD3's networks
            if key in old and key in fresh:
                out[key] = old[key]
        return out
    block = int(low.n_actions)
    n_old = old["buffer"]["data"]["before"].shape[1]
    outputs = old["q"][_last_layer(old["q"])[1]].shape[0]
    if outputs != n_old * block:
        raise TransferError(f"low level: the source acts with {outputs // max(n_old, 1)} actions, this task with {block}")
    out = dict(fresh)
    out["q"] = remap_net(old["q"], fresh["q"], index, block, "low level")
    out["q_target"] = remap_net(old["q_target"], fresh["q_target"], index, block, "low level (target)")
    if not keep_run:
        return out
    out["opt"] = _remap_adam(old["opt"], list(low.q.parameters()), index, block)
    out["steps"] = int(old["steps"])
    buf = copy.deepcopy(old["buffer"])
    for k in ("before", "after"):           # a sub-goal not tracked then counts as achieved: masked out
        buf["data"][k] = _remap_columns(buf["data"][k], index, True)
    out["buffer"] = buf
    return out


# -- a revision: the whole agent ----------------------------------------------------------------------


def revise_agent_state(old: dict[str, Any], agent: Any,
                       same_objective: bool = False) -> tuple[dict[str, Any], dict[str, Any]]:
    """The state of ``old`` (an HRL loop's ``state_dict()`` with a critic) carried over to ``agent``, the
    same loop built for the revised spec (module docstring). ``same_objective``: the revised spec has the
    same sub-goals, edges, signs, graph, prior, likelihood and inference settings, so the critic's Adam
    state and baseline and the low level's goal weights carry over too, and the run continues as if it
    had not been revised. Returns (state for ``agent.load_state_dict``, what was kept)."""
    fresh = agent.state_dict()
    critic, info = remap_critic_state(old["filter"]["critic"], agent.filter.critic, keep_run=True)
    if same_objective:
        src = old["filter"]["critic"]
        critic["optimizer"], critic["baseline"] = copy.deepcopy(src["optimizer"]), copy.deepcopy(src["baseline"])
    old_names, new_names = list(old["filter"]["critic"]["names"]), list(agent.names)
    index = name_index(old_names, new_names)
    same = old_names == new_names
    state = dict(old)
    state["high"] = remap_high_state(old["high"], fresh["high"], list(agent.high.q.parameters()), index)
    if "low" in old:
        state["low"] = remap_low_state(old["low"], fresh["low"], agent.low, index)
        if same_objective and "goal_weight" in old["low"]:
            state["low"]["goal_weight"] = old["low"]["goal_weight"]
    mask = old["filter"].get("mask")
    if mask is not None:
        mask = torch.as_tensor(_remap_columns(np.asarray(mask, dtype=bool)[None], index, True)[0])
    outcomes = old["filter"].get("outcomes", torch.zeros(0, len(old_names)))
    if any(i is None for i in index):       # stored episodes do not say whether they achieved a new sub-goal
        outcomes = torch.zeros(0, len(new_names))
    else:
        outcomes = torch.as_tensor(_remap_columns(np.asarray(outcomes.numpy(), dtype=np.float32), index, False))
    state["filter"] = {"critic": critic, "mask": mask, "outcomes": outcomes}
    if not same:
        state["pending"] = []
    info = {**info, "high_outputs_kept": sum(i is not None for i in index), "high_outputs": len(index),
            "pending_discarded": 0 if same else len(old.get("pending", [])),
            "outcomes_kept": int(outcomes.shape[0]),
            "critic_optimizer": "carried over" if same_objective else "restarted"}
    return state, info


# -- --init-from: another run's parts start a new run -------------------------------------------------
