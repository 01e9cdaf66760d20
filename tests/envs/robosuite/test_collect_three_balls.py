"""CollectThreeBalls: success counts balls in the bins; collect targets and routing over the wall."""

from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.mujoco


def test_collect_three_balls_success_counts_balls_in_bins(arm_env, put, achieved):
    e = arm_env("collect_three_balls")
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


def test_collect_target_and_wall_routing(arm_env):
    e = arm_env("collect_three_balls")
    t = e.unwrapped.task
    ball = t.object_position("ball_4")
    xyz, g = e.unwrapped.subgoal_target(e.unwrapped.subgoal_names.index("collect_ball_4"))
    np.testing.assert_allclose(xyz, [ball[0], ball[1], t.table_top + t.travel_clearance], atol=1e-9)
    assert g == -1.0
    same = t.travel_height(np.array([0.0, 0.2]), np.array([0.1, 0.25]))
    cross = t.travel_height(np.array([0.0, -0.2]), np.array([0.1, 0.25]))
    assert same == pytest.approx(t.table_top + t.travel_clearance)
    assert cross > t.table_top + t.wall_height + 2 * t.ball_radius
