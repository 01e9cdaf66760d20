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
