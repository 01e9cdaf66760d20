"""Check the sub-goal contract an environment must meet to train with HUBS-GO, in the spirit of
Stable-Baselines3's ``check_env`` for the Gymnasium API.

The HRL loop (Algorithm 1) reads an env through a small contract (docs/design.md, "Contract: tasks"):
a flat float32 ``Box`` observation, ``unwrapped.subgoal_names``, ``info["subgoals"]`` (one bool per
sub-goal) and ``info["is_success"]`` after ``reset`` and every ``step``, and a reset that the seed
fixes. :func:`check_env` plays a short seeded rollout and returns what is missing, each as one
:class:`Problem` naming the part of the contract and how to add it; an empty list means the env
meets it. Optional parts a low level reads (``subgoal_potential`` for the maze low level's shaping,
``subgoal_target`` for the scripted ones) are reported as notes, not problems, and so is an ``info``
sub-goal whose key the env's info never held during the rollouts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

__all__ = ["Problem", "check_env", "env_notes"]


@dataclass(frozen=True)
class Problem:
    """One part of the contract the env does not meet: ``what`` is missing, ``fix`` how to add it."""

    what: str
    fix: str

    def __str__(self) -> str:
        return f"{self.what}: {self.fix}"


def _flags(info: Any, n: int | None, where: str) -> list[Problem]:
    """The problems of ``info["subgoals"]`` and ``info["is_success"]`` after ``where``."""
    out = []
    if not isinstance(info, dict) or "subgoals" not in info:
        out.append(Problem(f'info["subgoals"] after {where}',
                           "missing; return one bool per sub-goal of unwrapped.subgoal_names, in that order, "
                           "e.g. info['subgoals'] = np.array([pred(state) for pred in predicates], dtype=bool)"))
    else:
        flags = np.asarray(info["subgoals"])
        if flags.dtype != bool or flags.ndim != 1 or (n is not None and flags.shape[0] != n):
            want = f"({n},)" if n is not None else "(N,)"
            out.append(Problem(f'info["subgoals"] after {where}',
                               f"a bool array of shape {want} is needed, got dtype {flags.dtype} and shape "
                               f"{flags.shape}; one flag per name in unwrapped.subgoal_names"))
    if not isinstance(info, dict) or "is_success" not in info:
        out.append(Problem(f'info["is_success"] after {where}',
                           "missing; report whether the task is solved (True on the step that solves it), "
                           "as Stable-Baselines3 reads it"))
    elif not isinstance(info["is_success"], (bool, np.bool_)):
        out.append(Problem(f'info["is_success"] after {where}',
                           f"a bool is needed, got {type(info['is_success']).__name__}"))
    return out


def _numbers(obs: Any) -> np.ndarray:
    """An observation of any space as one flat float64 array (a dict's values in key order, a text's
    bytes), so that two rollouts can be compared whatever the observation is."""
    if isinstance(obs, dict):
        parts = [_numbers(obs[k]) for k in sorted(obs, key=str)]
    elif isinstance(obs, (tuple, list)) and not all(isinstance(o, (int, float, np.number)) for o in obs):
        parts = [_numbers(o) for o in obs]
    elif isinstance(obs, str):
        return np.frombuffer(obs.encode(), np.uint8).astype(np.float64)
    else:
        return np.asarray(obs, dtype=np.float64).reshape(-1).copy()
    return np.concatenate(parts) if parts else np.zeros(0)


def check_env(env: gym.Env, steps: int = 50, seed: int = 0) -> list[Problem]:
    """What ``env`` lacks of the sub-goal contract, from two seeded rollouts of ``steps`` random steps
    (actions drawn from a generator of ``seed``, not from a global one). Does not close ``env``."""
    problems: list[Problem] = []
    space = env.observation_space
    if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
        problems.append(Problem("observation_space",
                                f"a flat gymnasium.spaces.Box is needed, got {space}; wrap the env in "
                                "gymnasium.wrappers.FlattenObservation"))
    elif space.dtype != np.float32:
        problems.append(Problem("observation_space",
                                f"float32 is needed, got {space.dtype}; wrap the env in "
                                "gymnasium.wrappers.TransformObservation(env, lambda o: o.astype(np.float32), ...)"))
    if not isinstance(env.action_space, (gym.spaces.Discrete, gym.spaces.Box)):
        problems.append(Problem("action_space", f"Discrete or Box is needed, got {env.action_space}"))
    names = getattr(env.unwrapped, "subgoal_names", None)
    n = None
    if (not isinstance(names, (list, tuple)) or not names or not all(isinstance(x, str) for x in names)
            or len(set(names)) != len(names)):
        problems.append(Problem("unwrapped.subgoal_names",
                                "missing or not a list of distinct names; set it on the env class, "
                                "e.g. self.subgoal_names = ['yellow_key', 'yellow_door', 'goal']"))
    else:
        n = len(names)
    rollouts = []
    for rollout in range(2):
        rng = np.random.default_rng(seed)
        obs, info = env.reset(seed=seed)
        trace = [_numbers(obs)]
        found = _flags(info, n, "reset")
        for _ in range(int(steps)):
            if isinstance(env.action_space, gym.spaces.Discrete):
                action = int(rng.integers(env.action_space.n))
            elif isinstance(env.action_space, gym.spaces.Box):
                low, high = env.action_space.low, env.action_space.high
                action = rng.uniform(np.maximum(low, -1.0), np.minimum(high, 1.0)).astype(env.action_space.dtype)
            else:
                break
            obs, reward, terminated, truncated, info = env.step(action)
            trace.append(_numbers(obs))
            found += [p for p in _flags(info, n, "step") if p not in found]
            if not np.isfinite(float(reward)):
                found.append(Problem("reward", f"a finite number is needed, got {reward!r}"))
            if terminated or truncated:
                obs, info = env.reset()
                trace.append(_numbers(obs))
        rollouts.append(trace)
        if rollout == 0:
            problems += found
    a, b = rollouts
    if len(a) != len(b) or any(x.shape != y.shape or not np.array_equal(x, y) for x, y in zip(a, b)):
        problems.append(Problem("reset(seed=...)",
                                "two rollouts with one seed and the same actions differ; seed every random "
                                "draw from the generator reset(seed) sets (self.np_random), not a global one"))
    return problems


def _has_potential(task: Any) -> bool:
    """Whether the env gives a ``subgoal_potential()``: a wrapper that has the method but answers None
    (an own env's wrapper, where the env has none) gives none."""
    potential = getattr(task, "subgoal_potential", None)
    if not callable(potential):
        return False
    try:
        return potential() is not None
    except Exception:       # noqa: BLE001 - it exists; what it needs (a reset) is the shaping's business
        return True


def env_notes(env: gym.Env) -> list[str]:
    """Optional parts of the contract the env lacks, and which low level misses them."""
    task = env.unwrapped
    notes = []
    grid = isinstance(env.action_space, gym.spaces.Discrete)    # the arms' learned low level reaches targets
    if grid and not _has_potential(task):
        notes.append("no subgoal_potential(): the learned grid low level trains without shaping "
                     "(--set low.shaping=0)")
    unreported = getattr(task, "unreported_info_keys", None)
    for name, key in (unreported() if callable(unreported) else {}).items():
        notes.append(f"sub-goal {name!r} reads info[{key!r}], which the env's info never held in these rollouts: "
                     "it is never achieved unless the env reports that key (check its spelling)")
    if not callable(getattr(task, "subgoal_target", None)):
        notes.append("no subgoal_target(i): the scripted low levels cannot be used (--low-level learned)")
    return notes


def scene_warnings(env: gym.Env, seed: int = 0) -> list[str]:
    """What the env's scene makes impossible, where it can tell (an arm scene: objects off the table,
    targets out of the arm's reach, at its seeded starts from ``seed`` on); resets the env."""
    scene = getattr(env.unwrapped, "scene_problems", None)
    return list(scene(seed=seed)) if callable(scene) else []
