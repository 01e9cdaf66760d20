"""PushAnyOne: success needs a cube on the pad of its own colour; push targets start behind the cube."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.mujoco


def test_push_any_one_success_needs_the_own_colour(arm_env, put, achieved):
    e = arm_env("push_any_one")
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


def test_push_target_starts_behind_the_cube_on_the_x_leg(arm_env):
    e = arm_env("push_any_one")
    t = e.unwrapped.task
    i = e.unwrapped.subgoal_names.index("push_red_to_red")   # red stands 15 cm to the side of the hand
    cube = t.object_position("red")
    xyz, g = e.unwrapped.subgoal_target(i)
    np.testing.assert_allclose(xyz, [cube[0] - t.standoff, cube[1], t.table_top + t.travel_clearance], atol=1e-9)
    assert g == 1.0


def test_a_push_to_another_row_goes_round_the_other_pads(arm_env):
    """Legs: x to the staging line short of the pads, y into the pad's row, x onto the pad."""
    t = arm_env("push_any_one").unwrapped.task
    pad = np.array([0.12, 0.15])
    axis, off = t._push_leg(np.array([-0.08, -0.15]), pad)
    assert axis == 0 and np.allclose(off, [pad[0] - t.stage_gap + 0.08, 0.0])
    axis, off = t._push_leg(np.array([pad[0] - t.stage_gap, -0.15]), pad)
    assert axis == 1 and np.allclose(off, [0.0, 0.30])
    axis, off = t._push_leg(np.array([pad[0] - t.stage_gap, 0.145]), pad)
    assert axis == 0 and np.allclose(off, [t.stage_gap, 0.0])
    assert t._push_leg(np.array([0.10, 0.145]), pad) is None
    axis, off = t._push_leg(np.array([-0.08, 0.15]), pad)      # in the pad's row: straight along x
    assert axis == 0 and np.allclose(off, [0.20, 0.0])


def test_a_scripted_push_counts_no_other_pad_on_the_way(arm_env):
    from hubsgo_ppl.agents.scripted_osc import ScriptedOSC

    e = arm_env("push_any_one")
    t = e.unwrapped.task
    names = e.unwrapped.subgoal_names
    # the cube whose pad lies in another row, so its push crosses the table towards the pads
    colour = next(c for c in t.colours
                  if abs(t.place_top(f"dest_{c}")[1] - t.object_position(c)[1]) > 0.1)
    i, ctrl, seen = names.index(f"push_{colour}_to_{colour}"), ScriptedOSC(), set()
    for _ in range(250):
        *_, info = e.step(ctrl.act(e, i))
        seen |= {n for n, a in zip(names, info["subgoals"]) if a and n.startswith("push_")}
        if info["subgoals"][i]:
            break
    assert info["is_success"] and seen == {f"push_{colour}_to_{colour}"}


def test_a_catalogue_adds_a_cube_colour_and_its_pad(tmp_path):
    from pathlib import Path

    from hubsgo_ppl.envs.robosuite import make_robosuite_task
    from hubsgo_ppl.specs import SpecError

    fixture = Path(__file__).resolve().parents[3] / "examples" / "arms" / "push_four.yaml"
    env = make_robosuite_task(str(fixture))
    try:
        env.reset(seed=1)
        t = env.unwrapped.task
        assert t.colours == ("red", "green", "blue", "yellow") and len(t.slots_y) == 4
        pads_y = sorted(float(t.place_top(f"dest_{c}")[1]) for c in t.colours)
        np.testing.assert_allclose(pads_y, [-0.15, -0.05, 0.05, 0.15], atol=1e-9)
        assert env.observation_space.shape == (9 + 4 * 7 + 4 * 3,)
        assert "push_yellow_to_yellow" in env.unwrapped.subgoal_names
    finally:
        env.close()
    bad = tmp_path / "bad.yaml"
    bad.write_text(fixture.read_text().replace("[red, green, blue, yellow]", "[red, pink]"))
    with pytest.raises(SpecError, match=r"bad.yaml: options.colours: \['red', 'pink'\] is not 1 to 4 distinct"):
        make_robosuite_task(str(bad))
