"""PushAnyOne: push any one cube onto the destination pad of its own colour (Sec. 4)."""

from __future__ import annotations

import numpy as np
from robosuite.models.objects import BoxObject
from robosuite.models.tasks import ManipulationTask
from robosuite.utils.placement_samplers import SequentialCompositeSampler, UniformRandomSampler

from .base import CLOSED, SubgoalKind, SubgoalManipulationEnv
from .options import COLOURS, colour_option

__all__ = ["PushAnyOne"]


class PushAnyOne(SubgoalManipulationEnv):
    """
    ## Description

    Three cubes (red, green, blue; 4 cm) stand in a row on the near half of the table; three flat
    destination pads of the same colours lie in a row on the far half, in a random order. Pushing
    *any one* cube onto the pad of its own colour solves the task; a cube on a pad of another colour
    does not count. The cubes are pushed (closed gripper, table height), not carried.

    ## Action Space

    ``Box(-1, 1, (4,), float32)``: OSC_POSITION end-effector displacement (x, y, z) and the gripper
    command (-1 open, +1 closed).

    ## Observation

    Flat ``float32`` vector (39): end-effector position (3) and quaternion (4), finger joints (2),
    each cube's position and quaternion (3 x 7), each pad's position (3 x 3).

    ## Rewards

    Sparse: 1 when some cube rests on its own-colour pad, else 0.

    ## Termination

    Terminated on success; truncated after ``horizon`` control steps (500 where the catalogue does not set it).

    ## Randomisation (seeded by ``reset(seed=...)``)

    Cube ``c`` (row slot y = -0.15, 0, 0.15 for red, green, blue) is drawn by a
    ``SequentialCompositeSampler`` of per-cube ``UniformRandomSampler``s: x in [-0.10, -0.06],
    y within 2 cm of its slot, no rotation. The pads' colours are a random permutation of the far
    slots (x = 0.12, y = -0.15, 0, 0.15). Pass ``placement_initializer`` to swap the cube sampler.

    A push whose pad lies in another row goes along x to a staging line ``stage_gap`` short of the
    pads, then along y, then onto the pad, so the cube never rests on or crosses another colour's
    pad (which would count as a wrong-colour push in the critic's evidence).

    The catalogue option ``colours`` (e.g. ``[red, green, blue, yellow]``, at most four of red,
    green, blue, yellow, magenta, cyan) sets the cubes and pads, one row each, spread over the same
    30 cm.

    ## Sub-goal catalogue (``envs/push_any_one.yaml``)

    | name | kind | achieved when |
    |---|---|---|
    | reach_red, reach_green, reach_blue | reach_above | hand within 2 cm of 8 cm above the cube |
    | push_X_to_Y (X, Y in red, green, blue) | push_to | cube X rests within 3 cm of pad Y's centre |

    ``push_X_to_X`` are the solutions; ``push_X_to_Y`` with Y != X are distractors.
    G*: one cube and the pad of its own colour, e.g. {reach_red, push_red_to_red}.

    ## Registered Configurations

    - ``hubsgo/PushAnyOne-v0`` (``hubsgo_ppl.envs.make("push_any_one")``)
    """

    colours = ("red", "green", "blue")
    max_colours = 4         # rows 10 cm apart at most: a cube's 2 cm jitter keeps clear of its neighbours
    # low sliding friction so a push at finger height slides the cube instead of tipping it over
    table_friction = (0.3, 5e-3, 1e-4)
    cube_friction = (0.3, 5e-3, 1e-4)
    cube_half = 0.02
    slots_y = (-0.15, 0.0, 0.15)    # with other colours: that many rows spread over the same 30 cm
    cube_x_range = (-0.10, -0.06)
    pad_x = 0.12
    push_tolerance = 0.03   # push_to: cube centre within this of the pad centre
    push_height = 0.018     # hand height above the table while pushing (fingertips clear the table)
    standoff = 0.04         # hand-to-cube-centre distance behind the cube before a push
    # a push leg (along x or y) is done within this of its end; the x leg is looser so the
    # small x drift of the y leg does not send the hand back round the cube
    leg_tolerance = (0.025, 0.01)
    push_step = 0.02        # how far ahead of the hand a push target lies (sets the push speed)
    # a cube that must change rows is first pushed to this gap short of the pads' row, then along it,
    # so it never rests on (or crosses) a pad other than its target
    stage_gap = 0.07

    def __init__(self, catalogue, *args, colours: tuple[str, ...] | list[str] = ("red", "green", "blue"), **kwargs):
        """``colours`` (a catalogue option): the cubes and their pads, one row each."""
        self.colours = colours = colour_option(catalogue, "colours", colours, self.max_colours)
        self.slots_y = tuple(float(y) for y in np.linspace(-0.15, 0.15, len(colours))) if len(colours) > 1 else (0.0,)
        super().__init__(catalogue, *args, **kwargs)

    def _load_model(self):
        arena = self._load_table()
        self.objects = {c: BoxObject(name=c, size=[self.cube_half] * 3, rgba=list(COLOURS[c]),
                                     friction=self.cube_friction) for c in self.colours}
        self.locations = {}
        for c, y in zip(self.colours, self.slots_y):
            self._add_location(arena, f"dest_{c}", (self.pad_x, y), rgba=COLOURS[c][:3] + (0.5,))
        cubes = list(self.objects.values())
        if self.placement_initializer is not None:
            self.placement_initializer.reset()
            self.placement_initializer.add_objects(cubes)
        else:
            self.placement_initializer = SequentialCompositeSampler(name="CubeSampler")
            for c, y in zip(self.colours, self.slots_y):
                self.placement_initializer.append_sampler(UniformRandomSampler(
                    name=f"{c}_sampler", mujoco_objects=self.objects[c], x_range=list(self.cube_x_range),
                    y_range=[y - 0.02, y + 0.02], rotation=0.0, ensure_object_boundary_in_range=False,
                    ensure_valid_placement=True, reference_pos=self.table_offset, z_offset=0.002, rng=self.rng))
        self.model = ManipulationTask(mujoco_arena=arena, mujoco_robots=[r.robot_model for r in self.robots],
                                      mujoco_objects=cubes)

    def _reset_internal(self):
        super()._reset_internal()
        self._reset_objects()
        for c, slot in zip(self.colours, self.rng.permutation(len(self.slots_y))):
            self._move_location(f"dest_{c}", (self.pad_x, self.slots_y[slot]))

    def _setup_observables(self):
        observables = super()._setup_observables()
        observables.update(self._object_sensors(list(self.colours), with_quat=True))
        observables.update(self._location_sensors([f"dest_{c}" for c in self.colours]))
        return observables

    def is_pushed_to(self, name: str, location: str, contacts: set | None = None) -> bool:
        """Cube ``name`` rests on the table within ``push_tolerance`` of ``location``'s centre."""
        pos = self.object_position(name)
        return (np.linalg.norm(pos[:2] - self.place_top(location)[:2]) < self.push_tolerance
                and abs(pos[2] - self.table_top - self.cube_half) < 0.01
                and not self.is_grasped(name, contacts))

    def _check_success(self) -> bool:
        """Some cube on the pad of its own colour."""
        contacts = self.contacts()
        return any(self.is_pushed_to(c, f"dest_{c}", contacts) for c in self.colours)

    # ------------------------------------------------------------------ push_to sub-goals
    def _subgoal_kinds(self) -> dict[str, SubgoalKind]:
        kinds = super()._subgoal_kinds()
        kinds["push_to"] = SubgoalKind({"object": "object", "to": "location"},
                                       lambda a, c: self.is_pushed_to(a["object"], a["to"], c), self._push_target,
                                       lasting=True)
        return kinds

    def _push_leg(self, cube: np.ndarray, pad: np.ndarray) -> tuple[int, np.ndarray] | None:
        """The current leg of a push as (axis, the cube's offset to the leg's end), None when done.

        A cube in the pad's row goes straight along x. Otherwise it goes along x to ``stage_gap``
        short of the pads' row, then along y into the pad's row, then along x onto the pad: it never
        stops on, or slides across, a pad of another colour (which would count as that pad's push)."""
        tol_x, tol_y = self.leg_tolerance
        stage_x = pad[0] - self.stage_gap
        if abs(pad[1] - cube[1]) > tol_y and cube[0] < stage_x - tol_x:
            return 0, np.array([stage_x - cube[0], 0.0])
        if abs(pad[1] - cube[1]) > tol_y:
            return 1, np.array([0.0, pad[1] - cube[1]])
        if abs(pad[0] - cube[0]) > tol_x:
            return 0, np.array([pad[0] - cube[0], 0.0])
        return None

    def _push_target(self, args, contacts):
        """Push in axis-aligned legs (:meth:`_push_leg`), each on a face normal so the cube slides straight.

        Per leg: get behind the cube on the leg's line (lifting over it when on the wrong side), then
        push with the target at most ``push_step`` ahead of the hand.
        """
        cube = self.object_position(args["object"])
        leg = self._push_leg(cube[:2], self.place_top(args["to"])[:2])
        if self.is_pushed_to(args["object"], args["to"], contacts) or leg is None:
            return self._route(cube + np.array([0.0, 0.0, self.hover_height])), CLOSED
        axis, offset = leg
        u = np.zeros(2)
        u[axis] = np.sign(offset[axis])
        eef = self.eef_position()
        z = self.table_top + self.push_height
        rel = eef[:2] - cube[:2]
        along = float(rel @ u)
        lateral = abs(float(rel[1 - axis]))
        # a push starts only well in line; once the hand is at the face it may drift a little more
        # (contact forces lift the hand by up to ~1.5 cm under OSC)
        pushing = along > -self.cube_half - 0.012
        slack, z_slack = (0.012, 0.02) if pushing else (0.006, 0.012)
        z_ok = abs(eef[2] - z) < z_slack
        if -self.standoff - 0.03 < along < -self.cube_half and lateral < slack and z_ok:
            ahead = min(abs(float(offset[axis])) + 0.008, self.push_step)   # aim a little past the centre
            return np.array([*(cube[:2] + (along + ahead) * u), z]), CLOSED
        behind = np.array([*(cube[:2] - self.standoff * u), z])
        if along < -self.cube_half - 0.008 and z_ok:
            return behind, CLOSED   # clear behind the cube: slide into line at table height
        return self._route(behind), CLOSED
