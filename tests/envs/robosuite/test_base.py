"""The shared arm-task machinery (SubgoalManipulationEnv), on StackCubes: the reach/grasp/place predicates,
their targets routed via travel height, and the sub-goal catalogue checks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hubsgo_ppl.envs.robosuite import make_robosuite_task
from hubsgo_ppl.specs import SpecError

pytestmark = pytest.mark.mujoco


def test_reach_above_predicate_and_target(arm_env, put, achieved):
    e = arm_env("stack_cubes")
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


def test_grasp_and_place_targets_route_via_travel_height(arm_env, achieved):
    e = arm_env("stack_cubes")
    t = e.unwrapped.task
    red = t.object_position("red")
    z_travel = t.table_top + t.travel_clearance
    assert t.eef_position()[2] > z_travel        # the hand starts above travel height
    xyz, g = e.unwrapped.subgoal_target(e.unwrapped.subgoal_names.index("grasp_red"))
    np.testing.assert_allclose(xyz, [red[0], red[1], z_travel], atol=1e-9)
    assert g == -1.0 and not achieved(e)["grasp_red"]
    # place without holding the cube: pick it up first, the same target as the grasp
    xyz_place, g = e.unwrapped.subgoal_target(e.unwrapped.subgoal_names.index("place_red_on_target"))
    np.testing.assert_allclose(xyz_place, xyz, atol=1e-9)
    assert g == -1.0
    with pytest.raises(IndexError, match="8 sub-goals"):
        e.unwrapped.subgoal_target(8)


def _bad_catalogue(tmp_path: Path, source: str, subgoal: str) -> str:
    text = Path(source).read_text().split("subgoals:")[0]
    path = tmp_path / "bad.yaml"
    path.write_text(text + "subgoals:\n  - " + subgoal + "\n")
    return str(path)


def test_bad_subgoals_name_the_problem(tmp_path, catalogue):
    source = catalogue("stack_cubes")
    with pytest.raises(SpecError, match=r"bad.yaml: subgoals\[0\] \(x\): kind 'fly' .*use one of: grasp, place_on"):
        make_robosuite_task(_bad_catalogue(tmp_path, source, "{name: x, kind: fly, args: {object: red}}"))
    with pytest.raises(SpecError, match=r"args.object: 'blue' is not an object .*use one of: red, green"):
        make_robosuite_task(_bad_catalogue(tmp_path, source, "{name: x, kind: grasp, args: {object: blue}}"))
    with pytest.raises(SpecError, match=r"args: unknown key\(s\) \['colour'\] for kind 'grasp'"):
        make_robosuite_task(_bad_catalogue(tmp_path, source, "{name: x, kind: grasp, args: {object: red, colour: 1}}"))
    with pytest.raises(SpecError, match="args.object: required for kind 'grasp'"):
        make_robosuite_task(_bad_catalogue(tmp_path, source, "{name: x, kind: grasp, args: {}}"))


def test_a_reach_above_height_below_the_object_is_refused(tmp_path, catalogue):
    """A negative height puts the hover point under the cube, inside the table: it would never be reached."""
    bad = "{name: x, kind: reach_above, args: {object: red, height: -0.1}}"
    with pytest.raises(SpecError, match=r"subgoals\[0\] \(x\): args.height: -0.1 is below the object"):
        make_robosuite_task(_bad_catalogue(tmp_path, catalogue("stack_cubes"), bad))
    make_robosuite_task(_bad_catalogue(tmp_path, catalogue("stack_cubes"),
                                       "{name: x, kind: reach_above, args: {object: red, height: 0.1}}")).close()


def test_a_place_option_alone_picks_carries_and_releases(arm_env, achieved):
    """The scripted controller runs StackCubes as two place options, each from a cube on the table,
    and the grasps are achieved on the way (the dependency chain the critic's evidence sees)."""
    from hubsgo_ppl.agents.scripted_osc import ScriptedOSC

    e = arm_env("stack_cubes")
    names, ctrl, seen = e.unwrapped.subgoal_names, ScriptedOSC(), set()
    for goal in ("place_red_on_target", "place_green_on_red"):
        i = names.index(goal)
        for _ in range(90):
            *_, info = e.step(ctrl.act(e, i))
            seen |= {n for n, a in zip(names, info["subgoals"]) if a}
            if info["subgoals"][i]:
                break
        assert info["subgoals"][i], goal
    assert info["is_success"] and {"grasp_red", "grasp_green"} <= seen


def test_robosuite_installation_notices_are_dropped_and_its_other_messages_kept(catalogue):
    """Importing the arm tasks and building one prints none of robosuite's notices about its own
    installation (five lines before every refusal), while any other robosuite message still shows."""
    import subprocess
    import sys

    code = ("import logging\n"
            "from hubsgo_ppl.envs.robosuite import make_robosuite_task\n"
            f"make_robosuite_task({str(catalogue('push_any_one'))!r}).close()\n"
            "logging.getLogger('robosuite_logs').warning('a real robosuite warning')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "macro file" not in out.stderr and "robosuite_models" not in out.stderr
    assert "mink" not in out.stderr and "controller configuration" not in out.stderr
    assert "a real robosuite warning" in out.stderr
