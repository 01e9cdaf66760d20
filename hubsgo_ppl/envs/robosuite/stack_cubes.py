"""StackCubes: stack the red cube on the target pad, then the green cube on the red one (Sec. 4)."""

from __future__ import annotations

import numpy as np
from robosuite.models.objects import BoxObject
from robosuite.models.tasks import ManipulationTask
from robosuite.utils.placement_samplers import UniformRandomSampler

from .base import SubgoalManipulationEnv
from .options import COLOURS, colour_option, listed_option

__all__ = ["StackCubes"]


class StackCubes(SubgoalManipulationEnv):
    """
    ## Description

    A Panda arm faces a table with a red and a green cube (4 cm) and a grey target pad. The task is
    solved when the red cube rests on the pad and the green cube rests on the red one, both released.
    Stacking in the other order does not count. The task has dependency relations: a cube must be
    grasped before it can be moved, and the lower (red) cube must be placed before the upper one.
    robosuite's ``Stack`` is the closest built-in; this task adds the pad and the ordering.

    ## Action Space

    ``Box(-1, 1, (4,), float32)``: OSC_POSITION end-effector displacement (x, y, z; 1 is about 1 cm
    per step at 20 Hz) and the gripper command (-1 open, +1 closed). The gripper stays pointing down.

    ## Observation

    Flat ``float32`` vector (32): end-effector position (3) and quaternion (4), finger joints (2),
    red cube position (3) and quaternion (4), green cube position and quaternion (7), pad position (3),
    and the end-effector-to-cube vectors (3 + 3).

    ## Rewards

    Sparse: 1 on the step the stack is complete, else 0.

    ## Termination

    Terminated on success; truncated after ``horizon`` control steps (500 where the catalogue does not set it).

    ## Randomisation (seeded by ``reset(seed=...)``)

    Cube positions: ``UniformRandomSampler`` over x in [-0.14, 0.02], y in [-0.16, 0.16] relative to
    the table centre, no rotation (OSC_POSITION cannot turn the hand), non-overlapping. The pad's
    centre is drawn uniformly in x in [0.08, 0.14], y in [-0.08, 0.08]. Pass ``placement_initializer``
    to swap the cube sampler.

    ## Catalogue options

    ``cubes`` (default ``[red, green]``): one to four colours of red, green, blue, yellow, magenta,
    cyan, the bottom of the stack first; the task is solved when they stand in that order on a pad.
    ``pads`` (default ``[target]``): the names of one to three pads, any of which may carry the stack;
    with more than one, each pad's centre is drawn in its own strip of y. A place option's route rises
    to its target's height before it crosses, so a cube carried onto a stack clears it. The observation
    grows by 10 per extra cube (position, quaternion, hand-to-cube) and 3 per extra pad.

    ## Sub-goal catalogue (``envs/stack_cubes.yaml``)

    | name | kind | achieved when |
    |---|---|---|
    | reach_above_red | reach_above | hand within 2 cm of 8 cm above the red cube |
    | grasp_red | grasp | both finger pads touch the red cube |
    | place_red_on_target | place_on | red cube released, centred on the pad |
    | reach_above_green | reach_above | hand within 2 cm of 8 cm above the green cube |
    | grasp_green | grasp | both finger pads touch the green cube |
    | place_green_on_red | place_on | green cube released, centred on the red cube |
    | place_green_on_target | place_on | (wrong order) green cube on the pad |
    | place_red_on_green | place_on | (wrong order) red cube on the green cube |

    A place option is complete on its own: not holding its cube, its target first picks the cube up
    (as ``collect`` does), so two options, place_red_on_target then place_green_on_red, solve the
    task, and the grasps are achieved on the way.

    G* (the dependency chain): grasp_red -> place_red_on_target -> grasp_green -> place_green_on_red.

    ## Registered Configurations

    - ``hubsgo/StackCubes-v0`` (``hubsgo_ppl.envs.make("stack_cubes")``)
    """

    cube_half = 0.02
    cube_friction = (1.0, 5e-3, 1e-4)
    pad_x_range = (0.08, 0.14)
    pad_y_range = (-0.08, 0.08)     # one pad; with more, each its own strip of y in [-0.16, 0.16]
    pad_half = 0.04
    max_cubes = 4                   # a four-cube stack stands 16 cm, still under the hand's reach
    max_pads = 3                    # three pads fill the 32 cm strip with 2 cm between them

    def __init__(self, catalogue, *args, cubes: tuple[str, ...] | list[str] = ("red", "green"),
                 pads: tuple[str, ...] | list[str] = ("target",), **kwargs):
        """``cubes`` (a catalogue option): the colours, bottom of the stack first; ``pads``: the names of
        the pads a stack may stand on."""
        self.cubes = colour_option(catalogue, "cubes", cubes, self.max_cubes)
        self.pads = listed_option(catalogue, "pads", pads, self.max_pads,
                                  lambda p: isinstance(p, str) and p.isidentifier() and p not in COLOURS,
                                  "names (letters, digits, _; not a cube colour), e.g. [target]")
        self.pad_strips = self._strips(len(self.pads))
        super().__init__(catalogue, *args, **kwargs)

    def _strips(self, n: int) -> list[tuple[float, float]]:
        """The y range of each pad's centre: the default range for one pad, else equal strips of
        [-0.16, 0.16] less the pad's half width and 1 cm, so no two pads touch."""
        if n == 1:
            return [self.pad_y_range]
        edges = np.linspace(-0.16, 0.16, n + 1)
        gap = self.pad_half + 0.01
        return [(float(lo + gap), float(hi - gap)) for lo, hi in zip(edges[:-1], edges[1:])]

    def _load_model(self):
        arena = self._load_table()
        self.objects = {c: BoxObject(name=c, size=[self.cube_half] * 3, rgba=list(COLOURS[c]),
                                     friction=self.cube_friction) for c in self.cubes}
        self.locations = {}
        for pad, (lo, hi) in zip(self.pads, self.pad_strips):
            self._add_location(arena, pad, (sum(self.pad_x_range) / 2, (lo + hi) / 2), rgba=(0.5, 0.5, 0.5, 1),
                               half_size=(self.pad_half, self.pad_half))
        cubes = list(self.objects.values())
        if self.placement_initializer is not None:
            self.placement_initializer.reset()
            self.placement_initializer.add_objects(cubes)
        else:
            self.placement_initializer = UniformRandomSampler(
                name="CubeSampler", mujoco_objects=cubes, x_range=[-0.14, 0.02], y_range=[-0.16, 0.16],
                rotation=0.0, ensure_object_boundary_in_range=False, ensure_valid_placement=True,
                reference_pos=self.table_offset, z_offset=0.002, rng=self.rng)
        self.model = ManipulationTask(mujoco_arena=arena, mujoco_robots=[r.robot_model for r in self.robots],
                                      mujoco_objects=cubes)

    def _reset_internal(self):
        super()._reset_internal()
        self._reset_objects()
        for pad, strip in zip(self.pads, self.pad_strips):
            self._move_location(pad, (self.rng.uniform(*self.pad_x_range), self.rng.uniform(*strip)))

    def _setup_observables(self):
        observables = super()._setup_observables()
        observables.update(self._object_sensors(list(self.cubes), with_quat=True))
        observables.update(self._location_sensors(list(self.pads)))
        observables.update(self._eef_to_sensors(list(self.cubes)))
        return observables

    def is_stacked(self, contacts: set | None = None) -> bool:
        """The bottom cube on some pad and every other cube on the one below it, all released."""
        contacts = self.contacts() if contacts is None else contacts
        bottom, *upper = self.cubes
        return (any(self.is_placed_on(bottom, pad, contacts) for pad in self.pads)
                and all(self.is_placed_on(c, below, contacts) for below, c in zip(self.cubes, upper)))

    def _check_success(self) -> bool:
        """The stack, in the catalogue's order, on a pad."""
        return self.is_stacked()
