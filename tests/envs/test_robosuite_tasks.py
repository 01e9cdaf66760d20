"""robosuite arm tasks: Gymnasium contract, seeding, success predicates, sub-goal predicates and targets.

Success and sub-goal predicates are checked by writing object poses straight into the simulator.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("robosuite", reason="robosuite is not installed: the arm-task tests are skipped (install "
                    "the 'robosuite' extra; 'make test' sets HUBSGO_REQUIRE_ROBOSUITE=1 and fails instead)")

import gymnasium as gym  # noqa: E402
from gymnasium.utils.env_checker import check_env  # noqa: E402

import hubsgo_ppl.envs as tasks  # noqa: E402
from hubsgo_ppl.envs.robosuite import make_robosuite_task  # noqa: E402
from hubsgo_ppl.resources import envs_dir  # noqa: E402
from hubsgo_ppl.specs import SpecError  # noqa: E402

pytestmark = pytest.mark.mujoco

TASKS = ["stack_cubes", "push_any_one", "collect_three_balls"]
OBS_DIM = {"stack_cubes": 32, "push_any_one": 39, "collect_three_balls": 27}
_cache: dict[str, gym.Env] = {}


def catalogue(task: str) -> str:
    return str(envs_dir() / f"{task}.yaml")


@pytest.fixture(scope="module", params=TASKS)
def env(request):
    # building a task compiles its MuJoCo model (~1 s); one instance per task serves the module
    if request.param not in _cache:
        _cache[request.param] = make_robosuite_task(catalogue(request.param))
    e = _cache[request.param]
    e.reset(seed=0)
    return e


def get(task: str) -> gym.Env:
    if task not in _cache:
        _cache[task] = make_robosuite_task(catalogue(task))
    e = _cache[task]
    e.reset(seed=0)
    return e


def put(env, name: str, xyz) -> None:
    """Write an object's pose (upright) into the sim and recompute positions and contacts."""
    t = env.unwrapped.task
    t.sim.data.set_joint_qpos(t.objects[name].joints[0], np.r_[xyz, 1.0, 0.0, 0.0, 0.0])
    t.sim.data.qvel[:] = 0.0
    t.sim.forward()


def achieved(env) -> dict[str, bool]:
    return dict(zip(env.unwrapped.subgoal_names, env.unwrapped.subgoal_achieved().tolist()))


# ---------------------------------------------------------------- Gymnasium contract
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
def test_seeded_rollouts_are_identical(task):
    a, b = get(task), make_robosuite_task(catalogue(task))
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


def test_step_validates_action_shape():
    e = get("stack_cubes")
    with pytest.raises(ValueError, match=r"shape \(3,\).*\(4,\)"):
        e.step(np.zeros(3))


# ---------------------------------------------------------------- success predicates
def test_stack_cubes_success_needs_the_right_order():
    e = get("stack_cubes")
    t = e.unwrapped.task
    pad = t.place_top("target")
    put(e, "red", pad + [0, 0, 0.02])
    put(e, "green", pad + [0, 0, 0.06])
    assert t._check_success() and t.reward() == 1.0
    got = achieved(e)
    assert got["place_red_on_target"] and got["place_green_on_red"] and not got["place_green_on_target"]
    put(e, "green", pad + [0.2, 0.1, 0.02])            # green off the stack
    assert not t._check_success() and achieved(e)["place_red_on_target"]
    put(e, "green", pad + [0, 0, 0.02])                 # wrong order: green below, red on top
    put(e, "red", pad + [0, 0, 0.06])
    got = achieved(e)
    assert not t._check_success() and t.reward() == 0.0
    assert got["place_green_on_target"] and got["place_red_on_green"] and not got["place_red_on_target"]


def test_push_any_one_success_needs_the_own_colour():
    e = get("push_any_one")
    t = e.unwrapped.task
    put(e, "red", t.place_top("dest_green") + [0, 0, 0.02])
    got = achieved(e)
    assert got["push_red_to_green"] and not got["push_red_to_red"] and not t._check_success()
    put(e, "red", t.place_top("dest_red") + [0.02, -0.015, 0.02])   # 2.5 cm off centre: inside tolerance
    assert achieved(e)["push_red_to_red"] and t._check_success()
    put(e, "red", t.place_top("dest_red") + [0.035, 0, 0.02])        # 3.5 cm off: outside
    assert not achieved(e)["push_red_to_red"] and not t._check_success()
    put(e, "blue", t.place_top("dest_blue") + [0, 0, 0.02])          # any one colour will do
    assert t._check_success()


def test_collect_three_balls_success_counts_balls_in_bins():
    e = get("collect_three_balls")
    t = e.unwrapped.task
    floor = t.table_top + 0.01 + t.ball_radius
    (rx, ry), (lx, ly) = t.bin_centres["bin_right"], t.bin_centres["bin_left"]
    put(e, "ball_0", [rx - 0.03, ry - 0.03, floor])
    put(e, "ball_1", [rx + 0.03, ry + 0.03, floor])
    assert not t._check_success() and t.num_collected() == 2
    put(e, "ball_4", [lx, ly, floor])                  # the third ball may come from the other side
    assert t._check_success()
    assert [k for k, v in achieved(e).items() if v] == ["collect_ball_0", "collect_ball_1", "collect_ball_4"]
    put(e, "ball_4", [lx + 0.07, ly, t.table_top + t.ball_radius])    # just outside the bin
    assert not t._check_success()
    put(e, "ball_4", [lx, ly, t.table_top + t.bin_rim + 0.05])        # above the bin, not in it
    assert not t._check_success()


# ---------------------------------------------------------------- sub-goal predicates and targets
def test_reach_above_predicate_and_target():
    e = get("stack_cubes")
    t = e.unwrapped.task
    i = e.unwrapped.subgoal_names.index("reach_above_red")
    eef = t.eef_position()
    put(e, "red", eef - [0.0, 0.0, t.hover_height + 0.01])
    assert achieved(e)["reach_above_red"]
    xyz, g = e.unwrapped.subgoal_target(i)
    np.testing.assert_allclose(xyz, t.object_position("red") + [0, 0, t.hover_height], atol=1e-9)
    assert g == -1.0
    put(e, "red", eef - [0.0, 0.03, t.hover_height])
    assert not achieved(e)["reach_above_red"]


def test_grasp_and_place_targets_route_via_travel_height():
    e = get("stack_cubes")
    t = e.unwrapped.task
    red = t.object_position("red")
    z_travel = t.table_top + t.travel_clearance
    assert t.eef_position()[2] > z_travel        # the hand starts above travel height
    xyz, g = e.unwrapped.subgoal_target(e.unwrapped.subgoal_names.index("grasp_red"))
    np.testing.assert_allclose(xyz, [red[0], red[1], z_travel], atol=1e-9)
    assert g == -1.0 and not achieved(e)["grasp_red"]
    # place without holding the cube: go above the support with the gripper open
    xyz, g = e.unwrapped.subgoal_target(e.unwrapped.subgoal_names.index("place_red_on_target"))
    np.testing.assert_allclose(xyz[:2], t.place_top("target")[:2], atol=1e-9)
    assert g == -1.0
    with pytest.raises(IndexError, match="8 sub-goals"):
        e.unwrapped.subgoal_target(8)


def test_push_target_starts_behind_the_cube_on_the_x_leg():
    e = get("push_any_one")
    t = e.unwrapped.task
    i = e.unwrapped.subgoal_names.index("push_red_to_red")   # red stands 15 cm to the side of the hand
    cube = t.object_position("red")
    xyz, g = e.unwrapped.subgoal_target(i)
    np.testing.assert_allclose(xyz, [cube[0] - t.standoff, cube[1], t.table_top + t.travel_clearance], atol=1e-9)
    assert g == 1.0


def test_collect_target_and_wall_routing():
    e = get("collect_three_balls")
    t = e.unwrapped.task
    ball = t.object_position("ball_4")
    xyz, g = e.unwrapped.subgoal_target(e.unwrapped.subgoal_names.index("collect_ball_4"))
    np.testing.assert_allclose(xyz, [ball[0], ball[1], t.table_top + t.travel_clearance], atol=1e-9)
    assert g == -1.0
    same = t.travel_height(np.array([0.0, 0.2]), np.array([0.1, 0.25]))
    cross = t.travel_height(np.array([0.0, -0.2]), np.array([0.1, 0.25]))
    assert same == pytest.approx(t.table_top + t.travel_clearance)
    assert cross > t.table_top + t.wall_height + 2 * t.ball_radius


# ---------------------------------------------------------------- catalogue errors
def _bad_catalogue(tmp_path: Path, subgoal: str) -> str:
    text = Path(catalogue("stack_cubes")).read_text().split("subgoals:")[0]
    path = tmp_path / "bad.yaml"
    path.write_text(text + "subgoals:\n  - " + subgoal + "\n")
    return str(path)


def test_bad_catalogues_name_the_problem(tmp_path):
    with pytest.raises(SpecError, match=r"bad.yaml: subgoals\[0\] \(x\): kind 'fly' .*use one of: grasp, place_on"):
        make_robosuite_task(_bad_catalogue(tmp_path, "{name: x, kind: fly, args: {object: red}}"))
    with pytest.raises(SpecError, match=r"args.object: 'blue' is not an object .*use one of: red, green"):
        make_robosuite_task(_bad_catalogue(tmp_path, "{name: x, kind: grasp, args: {object: blue}}"))
    with pytest.raises(SpecError, match=r"options: .*unexpected keyword.*'wall_heigth'"):
        make_robosuite_task(catalogue("stack_cubes"), wall_heigth=0.1)
    with pytest.raises(SpecError, match="env_class: 'Lift' is not a robosuite task"):
        make_robosuite_task(catalogue("stack_cubes"), env_class="Lift")
