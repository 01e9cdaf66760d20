"""A Gymnasium env of one's own as a task (family gym, hubsgo_ppl/envs/gym_task.py)."""

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import yaml

from hubsgo_ppl.envs import get_task, make
from hubsgo_ppl.envs.check import check_env
from hubsgo_ppl.envs.gym_task import GymTask, callable_ref, is_success, load_callable
from hubsgo_ppl.specs import SpecError

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture
def corridor(monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    import corridor_env

    return corridor_env


def _catalogue(tmp_path, subgoals, **options):
    options = options or {"entry_point": "corridor_env:make_corridor", "max_episode_steps": 30}
    path = tmp_path / "task.yaml"
    path.write_text(yaml.safe_dump({"task": "corridor", "family": "gym", "options": options, "subgoals": subgoals}))
    return path


SUBGOALS = [{"name": "switch_a", "kind": "predicate", "args": {"fn": "corridor_env:switch_on", "which": "a"}},
            {"name": "moved", "kind": "info", "args": {"key": "moved"}},
            {"name": "goal", "kind": "goal"}]


def test_each_kind_reads_the_state_the_info_and_the_success(tmp_path, corridor, monkeypatch):
    real_step = corridor.Corridor.step

    def step(self, action):         # the env reports "moved" itself
        before = self.pos
        obs, r, term, trunc, info = real_step(self, action)
        return obs, r, term, trunc, {**info, "moved": self.pos != before}

    monkeypatch.setattr(corridor.Corridor, "step", step)
    env = make(_catalogue(tmp_path, SUBGOALS), seed=0)
    assert env.unwrapped.subgoal_names == ["switch_a", "moved", "goal"]
    task = env.env.unwrapped
    obs, info = env.reset(seed=1)
    assert obs.dtype == np.float32 and obs.shape == (3,)
    assert info["subgoals"].tolist() == [False, False, False] and info["is_success"] is False
    task.pos = 4
    _, _, _, _, info = env.step(corridor.LEFT)           # to switch A's cell (3): moved, nothing pressed
    assert info["subgoals"].tolist() == [False, True, False]
    _, _, _, _, info = env.step(corridor.PRESS)
    assert info["subgoals"].tolist() == [True, False, False] and env.subgoal_achieved().tolist() == [True, False, False]
    task.pos = corridor.LENGTH - 2
    _, reward, terminated, _, info = env.step(corridor.RIGHT)    # onto the open goal: success
    assert (reward, terminated, info["is_success"]) == (1.0, True, True)
    assert info["subgoals"].tolist() == [True, True, True]


def test_success_is_the_envs_own_report_else_a_positive_terminal_reward():
    assert is_success({"is_success": False}, 1.0, True) is False
    assert is_success({"is_success": True}, 0.0, False) is True
    assert is_success({}, 1.0, True) is True
    assert is_success({}, 0.0, True) is False          # e.g. onto lava
    assert is_success({}, 1.0, False) is False         # a reward on the way


def test_the_task_meets_the_contract_and_its_seed_fixes_the_start(tmp_path, corridor):
    env = make(_catalogue(tmp_path, SUBGOALS), seed=0)
    assert check_env(env, steps=60) == []
    starts = {seed: env.reset(seed=seed)[0][0] for seed in range(8)}
    assert starts == {seed: env.reset(seed=seed)[0][0] for seed in range(8)} and len(set(starts.values())) > 1
    assert env.subgoal_potential() is None           # the corridor gives no shaping, and needs none


def test_a_registered_id_with_a_structured_observation_is_flattened(tmp_path):
    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], gym_id="Blackjack-v1")
    env = make(path, seed=0)
    space = env.observation_space              # Tuple(Discrete(32), Discrete(11), Discrete(2)), one-hot
    assert isinstance(space, gym.spaces.Box) and space.shape == (45,) and space.dtype == np.float32
    obs, _ = env.reset(seed=3)
    assert obs.sum() == 3.0 and set(np.unique(obs)) <= {0.0, 1.0}


@pytest.mark.parametrize("subgoals, options, message", [
    ([{"name": "g", "kind": "at", "args": {"x": 1}}], None, "unknown kind 'at' for family gym"),
    ([{"name": "g", "kind": "predicate"}], None, "kind predicate needs args.fn"),
    ([{"name": "g", "kind": "predicate", "args": {"fn": "corridor_env:nothing"}}], None, "has no 'nothing'"),
    ([{"name": "g", "kind": "predicate", "args": {"fn": "no_such_pkg.x:f"}}], None, "cannot import 'no_such_pkg.x'"),
    ([{"name": "g", "kind": "predicate", "args": {"fn": "corridor_env"}}], None, "is not 'module:function'"),
    ([{"name": "g", "kind": "goal"}], {"gym_id": "Pendulum-v1"}, "family gym trains on a Discrete action space"),
    ([{"name": "g", "kind": "goal"}], {"gym_id": "NoSuchEnv-v0"}, "options.gym_id: Environment `NoSuchEnv`"),
    ([{"name": "g", "kind": "goal"}], {"gym_id": "no_such_pkg:X-v0"},
     "cannot import 'no_such_pkg' for 'no_such_pkg:X-v0'; install its package or add its folder to PYTHONPATH"),
    ([{"name": "g", "kind": "goal"}], {"max_episode_steps": 5}, "give exactly one of entry_point"),
    ([{"name": "g", "kind": "goal"}], {"gym_id": "CartPole-v1", "horizon": 5}, "horizon"),
])
def test_a_bad_catalogue_is_one_line_naming_it(tmp_path, corridor, subgoals, options, message):
    path = _catalogue(tmp_path, subgoals, **(options or {}))
    with pytest.raises(SpecError, match=message) as err:
        GymTask(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_callable_only_this_process_holds_is_named_so_everywhere_else(monkeypatch):
    def nested(env, obs, info):
        return True

    ref, importable = callable_ref(nested)
    assert ref.startswith("<local>:nested#") and not importable
    assert load_callable(ref, "here") is nested and callable_ref(nested) == (ref, False)
    monkeypatch.setattr("hubsgo_ppl.envs.gym_task._LOCAL", {})      # another process
    with pytest.raises(SpecError, match="lambda or a nested function of the Python process that trained"):
        load_callable(ref, "there")
    assert callable_ref(np.mean) == ("numpy:mean", True)
    main = sys.modules["__main__"]
    nested.__module__, nested.__qualname__ = "__main__", "script_goal"
    monkeypatch.setattr(main, "script_goal", nested, raising=False)
    assert callable_ref(nested) == ("__main__:script_goal", False)
    monkeypatch.delattr(main, "script_goal")
    with pytest.raises(SpecError, match="defined in the script that trained the run"):
        load_callable("__main__:script_goal", "there")


def test_a_gym_catalogue_is_a_task_and_a_scripted_low_level_is_refused(tmp_path, corridor):
    from hubsgo_ppl.agents.config import ConfigError, resolve_hyper

    path = _catalogue(tmp_path, SUBGOALS)
    assert get_task(path).family == "gym"
    hyper = resolve_hyper("gym", "corridor", "hubsgo")
    assert hyper["low_level"] == "learned" and hyper["low"].get("shaping", 0.0) == 0.0
    with pytest.raises(ConfigError, match="has no scripted low level"):
        resolve_hyper("gym", "corridor", "hubsgo", low_level="scripted")
    with pytest.raises(ConfigError, match="agent hiro sets goals in a space it knows"):
        resolve_hyper("gym", "corridor", "hiro")


def test_shaping_without_a_potential_is_one_line_with_a_possible_fix(tmp_path, corridor, capsys):
    from hubsgo_ppl.cli import main

    path = _catalogue(tmp_path, SUBGOALS)
    assert main(["train", str(path), "--agent", "hdqn", "--set", "low.shaping=1", "--steps", "50",
                 "--out", str(tmp_path / "run"), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--set low.shaping=0" in err[0] and "obs_mode" not in err[0], err


@pytest.mark.parametrize("options, fragment", [
    ({"entry_point": "corridor_env:make_nothing", "max_episode_steps": 30}, "has no 'make_nothing'"),
    ({"gym_id": "MountainCarContinuous-v0"}, "trains on a Discrete action space"),
])
@pytest.mark.parametrize("command", ["check-env", "tasks"])
def test_tasks_refuses_the_gym_catalogues_check_env_refuses(tmp_path, corridor, capsys, options, fragment, command):
    from hubsgo_ppl.cli import main

    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], **options)
    assert main([command, str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err


def test_check_env_notes_an_info_key_the_env_never_reports(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    subgoals = [{"name": "slipped", "kind": "info", "args": {"key": "prob"}},     # FrozenLake reports info["prob"]
                {"name": "gems", "kind": "info", "args": {"key": "has_gemz"}}, {"name": "goal", "kind": "goal"}]
    path = _catalogue(tmp_path, subgoals, gym_id="FrozenLake-v1", max_episode_steps=20)
    assert main(["check-env", str(path), "--steps", "20"]) == 0
    out = capsys.readouterr().out
    notes = [line for line in out.splitlines() if "never held" in line]
    assert len(notes) == 1 and notes[0].startswith("note: sub-goal 'gems' reads info['has_gemz']"), out
    assert "meets the sub-goal contract" in out
    # FrozenLake has no subgoal_potential(), though the family's wrapper has the method (it answers None)
    assert "note: no subgoal_potential(): the learned grid low level trains without shaping" in out


@pytest.mark.parametrize("space, flattened", [(gym.spaces.Text(6), True),
                                              (gym.spaces.Sequence(gym.spaces.Discrete(2)), False)])
def test_a_text_observation_is_flattened_and_a_sequence_refused(space, flattened):
    from hubsgo_ppl.envs.gym_task import _flat_space

    if flattened:
        flat = _flat_space(space, "t.yaml")
        assert flat.shape == (6,) and flat.dtype == np.float32
    else:
        with pytest.raises(SpecError, match="t.yaml: the env's observation space .* cannot be flattened"):
            _flat_space(space, "t.yaml")


def _two_args(env, obs):
    return True


def _several(env, obs, info):
    return np.array([True, False])


def _raises(env, obs, info):
    return info["no_such_key"]


@pytest.mark.parametrize("subgoal, fragment", [
    ({"kind": "predicate", "args": {"fn": f"{__name__}:_two_args"}}, "cannot be called as fn(env, obs, info)"),
    ({"kind": "predicate", "args": {"fn": "corridor_env:switch_on", "whch": "a"}},
     "cannot be called as fn(env, obs, info, whch=...)"),
    ({"kind": "predicate", "args": {"fn": f"{__name__}:_several"}}, "gave an array of 2 elements"),
    ({"kind": "predicate", "args": {"fn": f"{__name__}:_raises"}},
     "raised KeyError: 'no_such_key' (in test_gym_task.py, line"),
    ({"kind": "info", "args": {"key": "action_mask"}}, "info['action_mask'] gave an array of 6 elements"),
])
def test_a_predicate_of_another_signature_or_an_array_is_one_line_exit_2(tmp_path, corridor, capsys, subgoal,
                                                                         fragment):
    from hubsgo_ppl.cli import main

    options = {"gym_id": "Taxi-v4"} if subgoal["kind"] == "info" else {}
    path = _catalogue(tmp_path, [{"name": "g", **subgoal}, {"name": "goal", "kind": "goal"}], **options)
    assert main(["check-env", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0] and "sub-goal 'g'" in err[0] and "unexpected" not in err[0], err


def _passes_kwargs_on(**kwargs):
    return gym.make("FrozenLake-v1", **kwargs)


@pytest.mark.parametrize("options", [{"gym_id": "FrozenLake-v1", "kwargs": {"is_slipery": False}},
                                     {"entry_point": "corridor_env:make_corridor", "kwargs": {"lenght": 9}},
                                     {"entry_point": f"{__name__}:_passes_kwargs_on", "kwargs": {"is_slipery": False}}])
def test_a_keyword_argument_the_env_does_not_take_is_one_line_exit_2(tmp_path, corridor, capsys, options):
    from hubsgo_ppl.cli import main

    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], **options)
    assert main(["check-env", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    bad = next(iter(options["kwargs"]))
    assert len(err) == 1 and "options.kwargs" in err[0] and f"keyword argument {bad!r}" in err[0], err


def test_an_env_without_a_time_limit_is_warned_of_once(tmp_path, corridor, capsys):
    GymTask(_catalogue(tmp_path, [{"name": "goal", "kind": "goal"}])).close()       # max_episode_steps 30
    assert "time limit" not in capsys.readouterr().err
    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], entry_point="corridor_env:make_corridor")
    GymTask(path).close()
    GymTask(path).close()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "has no time limit" in err[0] and "options.max_episode_steps" in err[0], err


def test_a_registered_id_named_with_its_module_is_built_after_importing_it(tmp_path, corridor, monkeypatch):
    (tmp_path / "registers_corridor.py").write_text(
        "import gymnasium as gym\n"
        "gym.register('RegisteredCorridor-v0', entry_point='corridor_env:make_corridor', max_episode_steps=30)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(gym.registry, "RegisteredCorridor-v0", raising=False)
    path = _catalogue(tmp_path, SUBGOALS[:1] + SUBGOALS[2:], gym_id="registers_corridor:RegisteredCorridor-v0")
    task = GymTask(path)
    try:
        assert task.subgoal_names == ["switch_a", "goal"]
    finally:
        task.close()
        gym.registry.pop("RegisteredCorridor-v0", None)
        sys.modules.pop("registers_corridor", None)


class _FromOne(gym.Env):
    """Actions 1 and 2 (Discrete(2, start=1)); the episode ends on action 2, successfully."""

    observation_space = gym.spaces.Box(0.0, 1.0, (1,), np.float32)
    action_space = gym.spaces.Discrete(2, start=1)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {}

    def step(self, action):
        assert self.action_space.contains(action), action
        return np.zeros(1, np.float32), float(action == 2), action == 2, False, {}


def _from_one():
    return _FromOne()


def test_an_action_space_that_starts_past_zero_gets_the_actions_it_numbers(tmp_path):
    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], entry_point=f"{__name__}:_from_one",
                      max_episode_steps=5)
    task = GymTask(path)
    try:
        assert task.action_space == gym.spaces.Discrete(2)
        task.reset(seed=0)
        assert task.step(0)[2:4] == (False, False)
        assert task.step(1)[4]["is_success"]
    finally:
        task.close()


def _frozen(is_slippery=True):
    return gym.make("FrozenLake-v1", is_slippery=is_slippery)


def test_a_keyword_argument_an_id_registered_with_a_callable_does_not_take_is_one_line_exit_2(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    gym.register("CallableFrozen-v0", entry_point=_frozen, max_episode_steps=20)
    try:
        path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], gym_id="CallableFrozen-v0",
                          kwargs={"is_slipery": False})
        assert main(["check-env", str(path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "options.kwargs" in err[0] and "keyword argument 'is_slipery'" in err[0], err
    finally:
        gym.registry.pop("CallableFrozen-v0", None)


class _Wider(_FromOne):
    """Declares a Box of 1 number, returns 3."""

    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return np.zeros(3, np.float32), {}


def _wider():
    return _Wider()


def test_an_observation_its_space_does_not_hold_is_one_line_exit_2(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], entry_point=f"{__name__}:_wider",
                      max_episode_steps=5)
    assert main(["check-env", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "observation of shape (3,)" in err[0] and "unexpected" not in err[0], err


class _PastDiscrete(_FromOne):
    """Declares Discrete(4), returns 4."""

    observation_space = gym.spaces.Discrete(4)
    action_space = gym.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        return 4, {}


def _past_discrete():
    return _PastDiscrete()


def test_an_observation_flatten_cannot_read_is_one_line_exit_2(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    path = _catalogue(tmp_path, [{"name": "goal", "kind": "goal"}], entry_point=f"{__name__}:_past_discrete",
                      max_episode_steps=5)
    assert main(["check-env", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the env returned an observation 4 (IndexError" in err[0], err
    assert "Discrete(4) does not hold" in err[0] and "unexpected" not in err[0], err
