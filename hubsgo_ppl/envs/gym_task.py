"""Any Gymnasium environment as a task (family ``gym``): the user's env plus the sub-goal contract.

A catalogue of family ``gym`` names the env and its sub-goals; :class:`GymTask` builds the env and
adds what HUBS-GO reads (docs/design.md, "Contract: tasks"): ``subgoal_names``,
``subgoal_achieved()``, ``info["subgoals"]`` and ``info["is_success"]``, and a flat float32 ``Box``
observation::

    task: corridor
    family: gym
    options: {entry_point: "corridor:make_corridor", kwargs: {length: 8}, max_episode_steps: 60}
    #  or    {gym_id: "CartPole-v1"}   (any registered id; "my_pkg:MyEnv-v0" imports my_pkg first)
    subgoals:
      - {name: switch_a, kind: predicate, args: {fn: "corridor:switch_on", which: a}}
      - {name: has_key, kind: info, args: {key: has_key}}
      - {name: goal, kind: goal}

Sub-goal kinds:

- ``predicate {fn: "module:function", ...}``: ``function(env, obs, info, **rest)`` is true when the
  sub-goal holds, where ``env`` is the user's env unwrapped (its state), ``obs`` its observation as it
  returns it (before flattening), ``info`` its info dict and ``rest`` the other ``args``;
- ``info {key: NAME}``: the env reports it itself, ``bool(info.get(NAME, False))``;
- ``goal``: the task is solved at this step (the success rule below).

Success: the env's own ``info["is_success"]`` where it reports one; otherwise a step that terminates
with a positive reward. Actions: ``Discrete`` only (the learned low level of HUBS-GO and h-DQN is a
goal-conditioned DQN). A callable that only the process that trained a run holds (a lambda, a
function defined in a function) is recorded as ``<local>:NAME``: that process can rebuild the env,
no other can (:func:`callable_ref`).
"""

from __future__ import annotations

import importlib
import inspect
import itertools
import sys
import traceback
from pathlib import Path
from typing import Any, Callable, ClassVar

import gymnasium as gym
import numpy as np
from pydantic import Field

from ..specs import SpecError, StrictModel, validate_spec
from .subgoals import Catalogue, SubgoalDef, load_catalogue

__all__ = ["GymTask", "GymOptions", "KINDS", "callable_ref", "load_callable", "is_success"]

#: the sub-goal kinds of the ``gym`` family, and the arguments each requires
KINDS = {"predicate": ("fn",), "info": ("key",), "goal": ()}

LOCAL = "<local>"
_LOCAL: dict[str, Callable[..., Any]] = {}
_LOCAL_IDS: dict[int, str] = {}
_COUNTER = itertools.count(1)


class GymOptions(StrictModel):
    """The ``options`` of a ``gym`` catalogue: which env, built with which keyword arguments."""

    spec_kind: ClassVar[str] = "gym task's options"

    entry_point: str | None = Field(default=None, description="'module:function' returning the env")
    gym_id: str | None = Field(default=None, description="a registered Gymnasium id")
    kwargs: dict[str, Any] = Field(default_factory=dict, description="keyword arguments of the env")
    max_episode_steps: int | None = Field(default=None, ge=1, description="truncate episodes after this many steps")


def callable_ref(fn: Callable[..., Any]) -> tuple[str, bool]:
    """``("module:qualname", True)`` for a callable any process can import by that name; otherwise a
    name only this process knows, ``("<local>:NAME#k", False)`` (a lambda, a function defined in a
    function, an object that is not its module's attribute). A function of a script (``__main__``) is
    recorded by its name in ``__main__`` and counts as not importable elsewhere (False)."""
    if not callable(fn):
        raise TypeError(f"{fn!r} is not callable")
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if module and qualname and "<" not in qualname:
        try:
            if _walk(importlib.import_module(module), qualname) is fn:
                return f"{module}:{qualname}", module != "__main__"
        except (ImportError, AttributeError):
            pass
    if id(fn) not in _LOCAL_IDS or _LOCAL.get(_LOCAL_IDS[id(fn)]) is not fn:
        name = (getattr(fn, "__name__", None) or type(fn).__name__).strip("<>")
        _LOCAL_IDS[id(fn)] = f"{LOCAL}:{name}#{next(_COUNTER)}"
        _LOCAL[_LOCAL_IDS[id(fn)]] = fn
    return _LOCAL_IDS[id(fn)], False


def _walk(obj: Any, qualname: str) -> Any:
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def load_callable(ref: str, where: str) -> Callable[..., Any]:
    """The callable ``ref`` ("module:qualname", or a ``<local>`` name of this process) names; a
    :class:`SpecError` naming ``where`` and the fix otherwise."""
    if ref in _LOCAL:
        return _LOCAL[ref]
    if ref.startswith(LOCAL + ":"):
        raise SpecError(f"{where}: {ref!r} was a lambda or a nested function of the Python process that trained "
                        "the run, which no other process can rebuild; define it at the top level of an importable "
                        "module and train again")
    module, sep, qualname = ref.partition(":")
    if not sep or not module or not qualname:
        raise SpecError(f"{where}: {ref!r} is not 'module:function', e.g. 'my_pkg.goals:has_key'")
    if module == "__main__":
        import __main__

        if not hasattr(__main__, qualname.split(".")[0]):
            raise SpecError(f"{where}: {ref!r} was defined in the script that trained the run, which this process "
                            "cannot import; move it into an importable module (e.g. my_pkg/goals.py) and train again")
    try:
        obj = _walk(importlib.import_module(module), qualname)
    except ModuleNotFoundError as exc:
        raise SpecError(f"{where}: cannot import {module!r} for {ref!r} ({exc}); install its package or add its "
                        "folder to PYTHONPATH") from None
    except AttributeError:
        raise SpecError(f"{where}: module {module!r} has no {qualname!r}; check the name in {ref!r}") from None
    if not callable(obj):
        raise SpecError(f"{where}: {ref!r} is a {type(obj).__name__}, not a function")
    return obj


def is_success(info: dict[str, Any], reward: float, terminated: bool) -> bool:
    """The success rule: the env's own ``info["is_success"]`` where it reports one; otherwise a step
    that terminates with a positive reward."""
    if "is_success" in info:
        return bool(info["is_success"])
    return bool(terminated and float(reward) > 0)


def _test(sg: SubgoalDef, source: str) -> Callable[[Any, Any, dict, bool], bool]:
    """The achievement test of one sub-goal: ``test(env, obs, info, success) -> bool``."""
    where = f"{source}: sub-goal {sg.name!r}"
    if sg.kind not in KINDS:
        from .minigrid.kinds import KINDS as MINIGRID_KINDS

        hint = (f"; {sg.kind} is a kind of family minigrid: a catalogue of a MiniGrid id takes family: minigrid"
                if sg.kind in MINIGRID_KINDS else "")
        raise SpecError(f"{where}: unknown kind {sg.kind!r} for family gym; use one of: {', '.join(KINDS)}{hint}")
    missing = [a for a in KINDS[sg.kind] if not isinstance(sg.args.get(a), str) or not sg.args.get(a)]
    if missing:
        raise SpecError(f"{where}: kind {sg.kind} needs args.{missing[0]} (a name), e.g. "
                        + ("{fn: 'my_pkg.goals:has_key'}" if sg.kind == "predicate" else "{key: has_key}"))
    if sg.kind == "goal":
        if sg.args:
            raise SpecError(f"{where}: kind goal takes no args; it holds when the task is solved")
        return lambda env, obs, info, success: success
    if sg.kind == "info":
        key = sg.args["key"]
        if len(sg.args) > 1:
            raise SpecError(f"{where}: kind info takes only args.key")
        return lambda env, obs, info, success: _truth(info.get(key, False), f"{where}: info[{key!r}]",
                                                        "an info sub-goal reads a key that holds a bool")
    fn = load_callable(sg.args["fn"], f"{where}: args.fn")
    rest = {k: v for k, v in sg.args.items() if k != "fn"}
    _check_call(fn, rest, f"{where}: args.fn {sg.args['fn']!r}")
    ref = f"{where}: args.fn {sg.args['fn']!r}"

    def test(env: Any, obs: Any, info: dict, success: bool) -> bool:
        try:
            value = fn(env, obs, info, **rest)
        except Exception as exc:        # the user's code: the sub-goal, the error and where it was raised
            frame = traceback.extract_tb(exc.__traceback__)[-1]
            raise SpecError(f"{ref} raised {type(exc).__name__}: {' '.join(str(exc).split())[:200]} (in "
                            f"{Path(frame.filename).name}, line {frame.lineno}); a predicate must give a truth "
                            "value in every state the env reaches") from exc
        return _truth(value, ref)
    return test


def _bind_error(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> TypeError | None:
    """Why ``fn(*args, **kwargs)`` would not bind to ``fn``'s signature; None where it would, or where
    ``fn`` has no signature to read (a builtin: called as it is)."""
    try:
        inspect.signature(fn).bind(*args, **kwargs)
    except TypeError as exc:
        return exc
    except ValueError:
        pass
    return None


def _check_call(fn: Callable[..., Any], rest: dict[str, Any], where: str) -> None:
    """Refuse, in one line, a predicate that cannot be called as ``fn(env, obs, info, **rest)``."""
    exc = _bind_error(fn, None, None, None, **rest)
    if exc is not None:
        call = ", ".join(["env", "obs", "info"] + [f"{k}=..." for k in rest])
        raise SpecError(f"{where} cannot be called as fn({call}) ({exc}); a predicate takes the env, its "
                        "observation and its info, then the sub-goal's other args by name")


def _truth(value: Any, where: str, fix: str = "return a bool, e.g. bool(x.any()) or bool(x.all())") -> bool:
    """``value`` as one truth value; a :class:`SpecError` for a numpy array of other than one element,
    which has none."""
    if isinstance(value, np.ndarray) and value.size != 1:
        raise SpecError(f"{where} gave an array of {value.size} elements, not one truth value; {fix}")
    return bool(value)


def _build(options: GymOptions, source: str, kwargs: dict[str, Any]) -> gym.Env:
    if (options.entry_point is None) == (options.gym_id is None):
        raise SpecError(f"{source}: options: give exactly one of entry_point ('module:function' returning the env) "
                        "and gym_id (a registered Gymnasium id)")
    kwargs = {**options.kwargs, **kwargs}
    if options.gym_id is not None:
        limit = {} if options.max_episode_steps is None else {"max_episode_steps": options.max_episode_steps}
        try:
            module, _, env_id = options.gym_id.rpartition(":")      # "my_pkg:MyEnv-v0": my_pkg registers it
            if module:
                importlib.import_module(module)
            spec = gym.spec(env_id)
            if kwargs and spec.entry_point is not None:      # a "module:Class" string, or the callable itself
                creator = spec.entry_point if callable(spec.entry_point) else \
                    gym.envs.registration.load_env_creator(spec.entry_point)
                own = {k: v for k, v in kwargs.items() if k not in inspect.signature(gym.make).parameters}
                _check_kwargs(creator, {**spec.kwargs, **own}, source, options.gym_id)
            return gym.make(options.gym_id, **limit, **kwargs)
        except ModuleNotFoundError as exc:
            raise SpecError(f"{source}: options.gym_id: cannot import {exc.name!r} for {options.gym_id!r}; "
                            "install its package or add its folder to PYTHONPATH") from None
        except gym.error.Error as exc:
            raise SpecError(f"{source}: options.gym_id: {' '.join(str(exc).split())[:300]}") from None
    factory = load_callable(options.entry_point, f"{source}: options.entry_point")
    _check_kwargs(factory, kwargs, source, options.entry_point)
    try:
        env = factory(**kwargs)
    except TypeError as exc:            # a factory that passes **kwargs on to a constructor that refuses one
        if not any(f"keyword argument {k!r}" in str(exc) for k in kwargs):
            raise
        raise _kwargs_error(source, options.entry_point, kwargs, exc) from None
    if not isinstance(env, gym.Env):
        raise SpecError(f"{source}: options.entry_point {options.entry_point!r} returned a {type(env).__name__}, "
                        "not a gymnasium.Env")
    return env if options.max_episode_steps is None else gym.wrappers.TimeLimit(env, options.max_episode_steps)


def _check_kwargs(creator: Callable[..., Any], kwargs: dict[str, Any], source: str, name: str) -> None:
    """Refuse, in one line, keyword arguments the env's constructor does not take."""
    exc = _bind_error(creator, **kwargs)
    if exc is not None:
        raise _kwargs_error(source, name, kwargs, exc)


def _kwargs_error(source: str, name: str, kwargs: dict[str, Any], exc: Exception) -> SpecError:
    return SpecError(f"{source}: options.kwargs: {name} cannot be built with {sorted(kwargs)} ({exc}); pass only "
                     "the keyword arguments it takes, in options.kwargs or --set env.KEY=VALUE")


def _flat_space(space: gym.Space, source: str) -> gym.spaces.Box | None:
    """The flat float32 observation space of ``space`` (None: it is one already)."""
    if isinstance(space, gym.spaces.Box) and len(space.shape) == 1 and space.dtype == np.float32:
        return None
    try:
        flat = gym.spaces.flatten_space(space)
    except NotImplementedError:
        flat = None
    if not isinstance(flat, gym.spaces.Box):
        raise SpecError(f"{source}: the env's observation space {space} cannot be flattened into numbers; wrap the "
                        "env so that it observes a Box, Discrete, or a Dict or Tuple of them")
    return gym.spaces.Box(flat.low.astype(np.float32), flat.high.astype(np.float32), dtype=np.float32)


#: the catalogues whose env has no time limit, already warned of in this process
_NO_LIMIT_WARNED: set[str] = set()


def _has_time_limit(env: gym.Env) -> bool:
    """Whether a ``TimeLimit`` wraps ``env`` (``max_episode_steps`` of its registration or of the options)."""
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.TimeLimit):
            return True
        env = env.env
    return False


class GymTask(gym.Env):
    """The user's env (``options``) with the sub-goal contract of the catalogue's sub-goals.

    Args:
        catalogue: path to a ``gym`` catalogue YAML (or a loaded :class:`Catalogue`).
        **kwargs: keyword arguments of the user's env, over ``options.kwargs`` (e.g. ``render_mode``).
    """

    def __init__(self, catalogue: str | Path | Catalogue, **kwargs: Any):
        cat = catalogue if isinstance(catalogue, Catalogue) else load_catalogue(catalogue)
        source = cat.source
        options = validate_spec(GymOptions, dict(cat.options), source=f"{source}: options")
        self._tests = [_test(sg, source) for sg in cat.subgoals]
        self.env = _build(options, source, kwargs)
        try:
            if not isinstance(self.env.action_space, gym.spaces.Discrete):
                raise SpecError(f"{source}: the env's action space is {self.env.action_space}; family gym trains "
                                "on a Discrete action space (the low level of HUBS-GO and h-DQN is a goal-conditioned "
                                "DQN)")
            self._space = self.env.observation_space
            flat = _flat_space(self._space, source)
        except BaseException:
            self.env.close()
            raise
        self.observation_space, self._source = flat or self._space, source
        self._flatten = flat is not None
        if not _has_time_limit(self.env) and source not in _NO_LIMIT_WARNED:
            _NO_LIMIT_WARNED.add(source)
            print(f"hubsgo: warning: {source}: the env has no time limit, so an episode lasts until the env ends it "
                  "and a run can pass its step budget, or never end; set options.max_episode_steps "
                  "(train_env's max_episode_steps)", file=sys.stderr)
        # the agents number actions from 0: a Discrete(n, start=k) env gets action + k
        self._action_start = int(self.env.action_space.start)
        self.action_space = gym.spaces.Discrete(int(self.env.action_space.n))
        self.metadata = dict(getattr(self.env, "metadata", {}) or {})
        self.render_mode = getattr(self.env, "render_mode", None)
        self.subgoal_names: list[str] = cat.names
        self._achieved = np.zeros(len(self._tests), dtype=bool)
        # the info sub-goals' keys, and the keys the env's info has held since it was built
        self._info_keys = {sg.name: sg.args["key"] for sg in cat.subgoals if sg.kind == "info"}
        self._seen_keys: set[Any] = set()

    def unreported_info_keys(self) -> dict[str, Any]:
        """The ``info`` sub-goals whose key the env's info has not held at any reset or step since it was
        built, by sub-goal name (`hubsgo check-env` notes them after its rollouts)."""
        return {name: key for name, key in self._info_keys.items() if key not in self._seen_keys}

    def _obs(self, obs: Any) -> np.ndarray:
        try:
            flat = np.asarray(gym.spaces.flatten(self._space, obs) if self._flatten else obs, dtype=np.float32)
            why = None if flat.shape == self.observation_space.shape else f"of shape {np.shape(obs)}"
        except (IndexError, ValueError, TypeError, KeyError, AssertionError) as exc:    # flatten's own complaint
            why = f"{' '.join(str(obs).split())[:80]} ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        if why is not None:
            raise SpecError(f"{self._source}: the env returned an observation {why}, which its observation_space "
                            f"{self._space} does not hold; make the two agree")
        return flat

    def _info(self, obs: Any, info: dict[str, Any], success: bool) -> dict[str, Any]:
        task = self.env.unwrapped
        self._seen_keys.update(info)
        self._achieved = np.array([test(task, obs, info, success) for test in self._tests], dtype=bool)
        return {**info, "subgoals": self._achieved.copy(), "is_success": success}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        info = dict(info)
        return self._obs(obs), self._info(obs, info, bool(info.get("is_success", False)))

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action + self._action_start
                                                                 if self._action_start else action)
        info = dict(info)
        success = is_success(info, reward, terminated)
        return self._obs(obs), reward, terminated, truncated, self._info(obs, info, success)

    def subgoal_achieved(self) -> np.ndarray:
        """Which sub-goals hold after the last ``reset`` or ``step``: bool array (N,)."""
        return self._achieved.copy()

    def subgoal_potential(self) -> Any:
        """The user's env's own ``subgoal_potential()`` (for ``low.shaping`` > 0), or None."""
        potential = getattr(self.env.unwrapped, "subgoal_potential", None)
        return potential() if callable(potential) else None

    def render(self) -> Any:
        return self.env.render()

    def close(self) -> None:
        self.env.close()
