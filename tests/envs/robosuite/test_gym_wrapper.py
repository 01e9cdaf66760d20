"""The Gymnasium face of the arm tasks: the env contract, spaces and infos, registration, seeding, action
checks, and the catalogue options that pick and configure the task class."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from gymnasium.utils.env_checker import check_env

import hubsgo_ppl.envs as tasks
from hubsgo_ppl.envs.robosuite import make_robosuite_task
from hubsgo_ppl.specs import SpecError

pytestmark = pytest.mark.mujoco

TASKS = ["stack_cubes", "push_any_one", "collect_three_balls"]
OBS_DIM = {"stack_cubes": 32, "push_any_one": 39, "collect_three_balls": 27}


@pytest.fixture(params=TASKS)
def env(request, arm_env):
    return arm_env(request.param)


@pytest.mark.filterwarnings("ignore:.*Box observation space m:UserWarning")   # unbounded by design
def test_check_env(env):
    check_env(env, skip_render_check=True)


def test_spaces_info_and_observation_layout(env):
    obs, info = env.reset(seed=3)
    task = env.unwrapped.task.catalogue.task
    assert env.observation_space.shape == (OBS_DIM[task],) and obs.dtype == np.float32
    assert env.action_space.shape == (4,)
    np.testing.assert_allclose(obs[:3], env.unwrapped.eef_position(), atol=1e-6)
    n = len(env.unwrapped.subgoal_names)
    assert 1 <= n <= 12
    assert env.unwrapped.subgoal_names == tasks.get_task(task).catalogue.names
    for i in (info, env.step(np.zeros(4, np.float32))[4]):
        assert i["subgoals"].dtype == bool and i["subgoals"].shape == (n,)
        assert i["is_success"] is False


def test_registered_through_gymnasium():
    ids = tasks.register()
    for task, title in zip(TASKS, ["StackCubes", "PushAnyOne", "CollectThreeBalls"]):
        assert f"hubsgo/{title}-v0" in ids
    e = gym.make("hubsgo/PushAnyOne-v0")
    e.reset(seed=1)
    assert e.unwrapped.subgoal_names[:3] == ["reach_red", "reach_green", "reach_blue"]
    e.close()


@pytest.mark.parametrize("task", TASKS)
def test_seeded_rollouts_are_identical(task, arm_env, catalogue):
    a, b = arm_env(task), make_robosuite_task(catalogue(task))
    actions = np.random.default_rng(7).uniform(-1, 1, (25, 4)).astype(np.float32)
    trajs = []
    for e in (a, b):
        obs, _ = e.reset(seed=11)
        traj = [obs]
        for act in actions:
            traj.append(e.step(act)[0])
        trajs.append(np.stack(traj))
    np.testing.assert_array_equal(trajs[0], trajs[1])
    # another seed moves the objects, and reset(seed) never touches the global NumPy RNG
    state = np.random.get_state()[1].copy()
    other, _ = b.reset(seed=12)
    assert not np.array_equal(other[9:], trajs[0][0][9:])
    np.testing.assert_array_equal(np.random.get_state()[1], state)
    b.close()


def test_step_validates_action_shape(arm_env):
    e = arm_env("stack_cubes")
    with pytest.raises(ValueError, match=r"shape \(3,\).*\(4,\)"):
        e.step(np.zeros(3))


def test_bad_options_name_the_problem(catalogue):
    with pytest.raises(SpecError, match=r"options: .*unexpected keyword.*'wall_heigth'"):
        make_robosuite_task(catalogue("stack_cubes"), wall_heigth=0.1)
    with pytest.raises(SpecError, match="env_class: 'Lift' is not a robosuite task"):
        make_robosuite_task(catalogue("stack_cubes"), env_class="Lift")


@pytest.mark.parametrize("key, value", [("horizon", "0"), ("horizon", "12.5"), ("control_freq", "-1"),
                                        ("travel_clearance", "0"), ("horizon", "many")])
@pytest.mark.parametrize("command", ["check-env", "tasks"])
def test_a_numeric_option_that_is_not_positive_is_one_line_naming_the_file_and_key(tmp_path, catalogue, capsys,
                                                                                   key, value, command):
    import yaml

    from hubsgo_ppl.cli import main

    data = yaml.safe_load(open(catalogue("push_any_one")).read())
    data["options"][key] = yaml.safe_load(value)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main([command, str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"bad.yaml: options.{key}: " in err[0] and "is not a positive" in err[0], err


def _edited(tmp_path, catalogue, task, edit):
    import yaml

    data = yaml.safe_load(open(catalogue(task)).read())
    edit(data)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def _subgoal(**fields):
    return lambda data: data["subgoals"].append(fields)


BAD_SCENES = [
    ("push_any_one", lambda d: d["options"].update(colours=["magenta", "orange"]), "options.colours: "),
    ("push_any_one", lambda d: d["options"].update(cubes=["red", "green"]), "unexpected keyword argument 'cubes'"),
    ("stack_cubes", lambda d: d["options"].update(cubes=["blue", "blue"]), "options.cubes: ['blue', 'blue']"),
    ("stack_cubes", _subgoal(name="x", kind="place_on", args={"object": "red", "onto": "left_pad"}),
     "args.onto: 'left_pad' is not a place of StackCubes"),
    ("stack_cubes", _subgoal(name="x", kind="place_on", args={"object": "red", "onto": "red"}),
     "args.onto: 'red' is the object itself; name another place of StackCubes"),
    ("push_any_one", _subgoal(name="x", kind="goal"), "kind 'goal' is not known to PushAnyOne"),
    ("push_any_one", _subgoal(name="x", kind="push_to", args={"object": "red", "to": "dest_pink"}),
     "args.to: 'dest_pink' is not a location of PushAnyOne"),
]


@pytest.mark.parametrize("task, edit, fragment", BAD_SCENES)
@pytest.mark.parametrize("command", [["check-env"], ["tasks"], ["tasks", "--model", "independent"]])
def test_tasks_and_check_env_refuse_the_same_arm_catalogues(tmp_path, catalogue, capsys, task, edit, fragment,
                                                            command):
    from hubsgo_ppl.cli import main

    path = _edited(tmp_path, catalogue, task, edit)
    assert main([command[0], path, *command[1:]]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and fragment in err[0], err


@pytest.mark.parametrize("key, value", [("initialization_noise", "lots"), ("initialization_noise", "{magnitude: 0.1}"),
                                        ("initialization_noise", "{magnitude: 100, type: gaussian}"),
                                        ("table_full_size", "[1, 2]"), ("table_full_size", "big"),
                                        ("robots", "Foo"), ("robots", "Baxter"), ("robots", "GR1"),
                                        ("robots", "PandaOmron"), ("robots", "XArm7"), ("seed", "abc"),
                                        ("placement_initializer", "3"), ("control_freq", "1000")])
def test_a_scene_option_robosuite_would_fail_on_is_one_line_naming_the_file_and_key(tmp_path, catalogue, capsys,
                                                                                     key, value):
    import yaml

    from hubsgo_ppl.cli import main

    data = yaml.safe_load(open(catalogue("push_any_one")).read())
    data["options"][key] = yaml.safe_load(value)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(data))
    assert main(["tasks", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"bad.yaml: options.{key}: " in err[0], err


@pytest.mark.parametrize("key, value", [("robots", "Baxter"), ("control_freq", 1000), ("table_full_size", [1, 2])])
def test_an_override_of_a_scene_option_is_checked_as_the_catalogues_own(catalogue, key, value):
    with pytest.raises(SpecError, match=f"push_any_one.yaml: options.{key}: "):
        make_robosuite_task(catalogue("push_any_one"), **{key: value})


def test_set_env_robots_is_refused_in_one_line(tmp_path, capsys):
    from hubsgo_ppl.cli import main

    code = main(["train", "push_any_one", "--steps", "10", "--set", "env.robots=Baxter", "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "options.robots: 'Baxter' is not one of the single arms" in err[0], err


def test_tasks_lists_the_budget_a_catalogue_without_one_takes_and_notes_nothing_of_steps(capsys):
    from pathlib import Path

    from hubsgo_ppl.cli import main

    arms = Path(__file__).resolve().parents[3] / "examples" / "arms"
    assert main(["tasks", str(arms / "push_four.yaml"), "--model", str(arms / "push_four-spec.yaml")]) == 0
    out, err = capsys.readouterr()
    assert ("    budget: 30,000 env steps, the robosuite family's 100 episodes of the task's 300-step horizon (train's "
            "default; --steps sets another)") in out.splitlines()
    assert "--steps" not in err
