"""CollectThreeBalls: drop any three of six balls into the bins; a wall splits them in two (Sec. 4)."""

from __future__ import annotations

import numpy as np
from robosuite.models.objects import BallObject
from robosuite.models.tasks import ManipulationTask
from robosuite.utils.placement_samplers import SequentialCompositeSampler, UniformRandomSampler

from .base import CLOSED, OPEN, SubgoalKind, SubgoalManipulationEnv

__all__ = ["CollectThreeBalls"]


class CollectThreeBalls(SubgoalManipulationEnv):
    """
    ## Description

    Six balls (radius 2.2 cm) lie on the table, three on each side of a wall that runs along the
    x axis at y = 0 (from x = -0.25 to the far edge, ``wall_height`` tall). Each side has an open bin
    (12 x 12 cm, 4 cm rim) at its far end. A ball is *collected* when it lies inside either bin;
    collecting any three solves the task. The arm may carry a ball to either bin, but crossing the
    wall means climbing over it: :meth:`travel_height` routes the hand over the wall top (plus
    clearance) whenever a move crosses y = 0, so three balls from one side cost less end-effector
    travel than a mix.

    ## Action Space

    ``Box(-1, 1, (4,), float32)``: OSC_POSITION end-effector displacement (x, y, z) and the gripper
    command (-1 open, +1 closed).

    ## Observation

    Flat ``float32`` vector (27): end-effector position (3) and quaternion (4), finger joints (2),
    each ball's position (6 x 3).

    ## Rewards

    Sparse: 1 when three or more balls are in the bins, else 0.

    ## Termination

    Terminated on success; truncated after ``horizon`` control steps (500 where the catalogue does not set it).

    ## Randomisation (seeded by ``reset(seed=...)``)

    Balls 0-2 (y < 0, the "right" side seen from the robot) and 3-5 (y > 0) are drawn by a
    ``SequentialCompositeSampler`` of two ``UniformRandomSampler``s over x in [-0.16, 0.04] and
    |y| in [0.14, 0.28], non-overlapping. Pass ``placement_initializer`` to swap it.

    ## Sub-goal catalogue (``envs/collect_three_balls.yaml``)

    | name | kind | achieved when |
    |---|---|---|
    | collect_ball_0 ... collect_ball_5 | collect | the ball lies inside a bin |

    ``collect`` is a pick-and-drop: its target approaches the ball open, closes on it, carries it at
    travel height to the bin on the hand's side of the wall and opens above it.
    G*: three balls on the same side, {collect_ball_0, 1, 2} or {collect_ball_3, 4, 5}.

    ## Registered Configurations

    - ``hubsgo/CollectThreeBalls-v0`` (``hubsgo_ppl.envs.make("collect_three_balls")``)
    """

    ball_radius = 0.022
    num_balls = 6
    wall_x = (-0.25, 0.4)
    wall_thickness = 0.01
    bin_centres = {"bin_right": (0.16, -0.21), "bin_left": (0.16, 0.21)}
    bin_inner_half = 0.06
    bin_rim = 0.04
    ball_x_range = (-0.16, 0.04)
    ball_y_range = (0.14, 0.28)   # the Panda hand reaches ~10 cm either side of the fingers
    needed = 3
    ball_friction = (1.0, 5e-3, 2e-3)   # sliding, torsional, rolling (needs condim 6)

    def __init__(self, *args, wall_height: float = 0.15, **kwargs):
        if not wall_height > 0:
            raise ValueError(f"wall_height must be > 0 metres, got {wall_height}")
        self.wall_height = float(wall_height)
        super().__init__(*args, **kwargs)

    def _load_model(self):
        arena = self._load_table()
        top = self.table_top
        length = self.wall_x[1] - self.wall_x[0]
        self._add_static_box(arena, "wall", (sum(self.wall_x) / 2, 0.0, top + self.wall_height / 2),
                             (length / 2, self.wall_thickness / 2, self.wall_height / 2), (0.6, 0.4, 0.2, 1))
        h, t = self.bin_inner_half, 0.005
        for name, (x, y) in self.bin_centres.items():
            self._add_static_box(arena, f"{name}_floor", (x, y, top + t), (h + 2 * t, h + 2 * t, t), (0.3, 0.3, 0.3, 1))
            for k, (dx, dy, sx, sy) in enumerate([(h + t, 0, t, h + 2 * t), (-h - t, 0, t, h + 2 * t),
                                                  (0, h + t, h, t), (0, -h - t, h, t)]):
                self._add_static_box(arena, f"{name}_side{k}", (x + dx, y + dy, top + self.bin_rim / 2),
                                     (sx, sy, self.bin_rim / 2), (0.3, 0.3, 0.3, 1))
        self.objects = {f"ball_{i}": BallObject(name=f"ball_{i}", size=[self.ball_radius],
                                                 rgba=[0.9, 0.6, 0.1, 1] if i < 3 else [0.1, 0.6, 0.9, 1],
                                                 friction=self.ball_friction)
                        for i in range(self.num_balls)}
        for ball in self.objects.values():
            for geom in ball.get_obj().iter("geom"):
                geom.set("condim", "6")   # rolling friction: a nudged ball stops instead of rolling away
        self.locations = {}
        balls = list(self.objects.values())
        if self.placement_initializer is not None:
            self.placement_initializer.reset()
            self.placement_initializer.add_objects(balls)
        else:
            self.placement_initializer = SequentialCompositeSampler(name="BallSampler")
            lo, hi = self.ball_y_range
            for side, y_range in (("right", [-hi, -lo]), ("left", [lo, hi])):
                group = balls[:3] if side == "right" else balls[3:]
                self.placement_initializer.append_sampler(UniformRandomSampler(
                    name=f"{side}_sampler", mujoco_objects=group, x_range=list(self.ball_x_range), y_range=y_range,
                    rotation=0.0, ensure_object_boundary_in_range=False, ensure_valid_placement=True,
                    reference_pos=self.table_offset, z_offset=0.001, rng=self.rng))
        self.model = ManipulationTask(mujoco_arena=arena, mujoco_robots=[r.robot_model for r in self.robots],
                                      mujoco_objects=balls)

    def _reset_internal(self):
        super()._reset_internal()
        self._reset_objects()

    def _setup_observables(self):
        observables = super()._setup_observables()
        observables.update(self._object_sensors(list(self.objects), with_quat=False))
        return observables

    # ------------------------------------------------------------------ predicates
    def is_collected(self, name: str) -> bool:
        """The ball lies inside a bin: centre within the bin's inner square and below its rim."""
        pos = self.object_position(name)
        inside = any(np.all(np.abs(pos[:2] - np.array(c)) < self.bin_inner_half) for c in self.bin_centres.values())
        return bool(inside and pos[2] < self.table_top + self.bin_rim)

    def num_collected(self) -> int:
        return sum(self.is_collected(n) for n in self.objects)

    def _check_success(self) -> bool:
        """Three or more balls in the bins."""
        return self.num_collected() >= self.needed

    # ------------------------------------------------------------------ routing over the wall
    def travel_height(self, start_xy: np.ndarray, goal_xy: np.ndarray) -> float:
        """Over the wall (top + clearance) when the move crosses y = 0 along the wall, else the default."""
        base = super().travel_height(start_xy, goal_xy)
        crosses = start_xy[1] * goal_xy[1] < 0 and max(start_xy[0], goal_xy[0]) > self.wall_x[0]
        if crosses:
            return max(base, self.table_top + self.wall_height + 2 * self.ball_radius + 0.03)
        return base

    # ------------------------------------------------------------------ collect sub-goals
    def _subgoal_kinds(self):
        kinds = super()._subgoal_kinds()
        kinds["collect"] = SubgoalKind({"object": "object"}, lambda a, c: self.is_collected(a["object"]),
                                       self._collect_target)
        return kinds

    def _collect_target(self, args, contacts):
        """Pick the ball, carry it to the bin on the hand's side of the wall, open above it."""
        name = args["object"]
        if self.is_collected(name):
            return self._route(self.object_position(name) + np.array([0, 0, self.hover_height])), OPEN
        if not self.is_grasped(name, contacts):
            return self._pick(name, contacts)
        eef = self.eef_position()
        bin_xy = min(self.bin_centres.values(), key=lambda c: np.linalg.norm(np.array(c) - eef[:2]))
        drop = np.array([bin_xy[0], bin_xy[1], self.table_top + self.bin_rim + self.ball_radius + 0.03])
        goal = drop + (eef - self.object_position(name))
        if np.linalg.norm(eef - goal) < self.grip_tolerance:
            return goal, OPEN
        return self._route(goal), CLOSED
