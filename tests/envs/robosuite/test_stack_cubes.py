"""StackCubes: success needs the cubes stacked in the right order."""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.mujoco


def test_stack_cubes_success_needs_the_right_order(arm_env, put, achieved):
    e = arm_env("stack_cubes")
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
