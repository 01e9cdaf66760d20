"""What a built arm scene makes impossible, read from the scene itself after a reset: an object that
does not start over the table (it falls to the floor), or a sub-goal target that no pose of the arm
reaches (a table that moves the robot's base away, a travel clearance or hover height of metres).

The arm's reach is bounded from its own kinematic chain, whatever the robot: the end effector is at
most the sum of the fixed offsets between the bodies from the robot's base to its grip site away from
the base (each joint only turns the next offset), so a target farther than that is out of reach.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["SCENE_RESETS", "arm_reach", "scene_problems"]

#: the seeded starts a scene is checked on: each draws its own placement, and a table too small for the
#: placements puts an object off it at some starts only
SCENE_RESETS = 10

#: how far past the table's edge an object's centre may start (metres): half a small object's width
EDGE_SLACK = 0.01


def arm_reach(task: Any) -> tuple[np.ndarray, float]:
    """(world position of the robot's base, an upper bound in metres on the distance from it to the
    grip site in any pose)."""
    model = task.sim.model
    root = model.body_name2id(task.robots[0].robot_model.root_body)
    site = task.robots[0].eef_site_id["right"]
    reach = float(np.linalg.norm(model.site_pos[site]))
    body = int(model.site_bodyid[site])
    while body != root and body > 0:
        reach += float(np.linalg.norm(model.body_pos[body]))
        for j in range(int(model.body_jntadr[body]), int(model.body_jntadr[body] + model.body_jntnum[body])):
            reach += 2 * float(np.linalg.norm(model.jnt_pos[j]))    # a joint turning about a point off the origin
        body = int(model.body_parentid[body])
    return np.array(task.sim.data.body_xpos[root]), reach


def scene_problems(task: Any) -> list[str]:
    """The objects that start off the table and the sub-goals whose target lies out of the arm's reach,
    one sentence each, on the task's current state (read it right after a reset)."""
    problems = []
    half = np.array(task.table_full_size[:2]) / 2 + EDGE_SLACK
    for name in task.objects:
        xy = task.object_position(name)[:2] - task.table_offset[:2]
        if np.any(np.abs(xy) > half):
            problems.append(f"object {name!r} starts at x={xy[0]:+.2f}, y={xy[1]:+.2f} m from the table's centre, "
                            f"off a table of {task.table_full_size[0]} x {task.table_full_size[1]} m: it falls to "
                            "the floor (options.table_full_size)")
    base, reach = arm_reach(task)
    far = {}
    for i, name in enumerate(task.subgoal_names):
        distance = float(np.linalg.norm(np.asarray(task.subgoal_target(i)[0]) - base))
        if distance > reach:
            far[name] = distance
    if far:
        span = f"{min(far.values()):.2f}" + (f"-{max(far.values()):.2f}" if max(far.values()) > min(far.values()) + 5e-3
                                             else "")
        problems.append(f"the target of {', '.join(far)} ({len(far)} of {len(task.subgoal_names)} sub-goals) lies "
                        f"{span} m from the arm's base, which reaches at most {reach:.2f} m (check "
                        "options.table_full_size, options.travel_clearance and reach_above heights)")
    return problems
