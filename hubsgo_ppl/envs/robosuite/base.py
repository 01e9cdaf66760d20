"""Shared base of the robosuite arm tasks: a ``ManipulationEnv`` with the sub-goal interface.

The paper's arm tasks (Sec. 4: StackCubes, PushAnyOne, CollectThreeBalls) all use a Panda arm under
operational-space control (OSC_POSITION: the action is a Cartesian end-effector displacement in
[-1, 1]^3 plus a gripper command in [-1, 1], -1 open, +1 closed) and a sparse reward (1 on success,
else 0). This module holds what they share:

* the controller configuration and the table arena,
* explicit seeding: robosuite's placement samplers take an ``rng``; :meth:`reseed` hands every
  sampler (and the robot's initial-joint noise) one ``np.random.Generator``, so nothing reads the
  global ``np.random`` (robosuite #347, #600),
* the sub-goal machinery of ``docs/design.md``: each catalogue entry (``envs/*.yaml``) is compiled
  into an achievement predicate and a state-dependent target ``(xyz, gripper)`` for the low level.

A sub-goal's target is a *waypoint*: it is re-evaluated on every call from the current state, so a
low level that just tracks it (``hubsgo_ppl.agents.scripted_osc.ScriptedOSC``, or a learned
goal-conditioned policy) lifts to a travel height, moves across, descends and actuates the gripper.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from robosuite.controllers import load_composite_controller_config, load_part_controller_config
from robosuite.environments.manipulation.manipulation_env import ManipulationEnv
from robosuite.models.arenas import TableArena
from robosuite.models.objects import MujocoObject
from robosuite.utils.mjcf_utils import new_body, new_geom
from robosuite.utils.observables import Observable, sensor
from robosuite.utils.placement_samplers import ObjectPositionSampler, SequentialCompositeSampler

from ...specs import SpecError
from ..subgoals import Catalogue, SubgoalDef
from .options import DEFAULT_HORIZON

__all__ = ["SubgoalManipulationEnv", "SubgoalKind", "osc_position_controller", "set_sampler_rng"]

OPEN, CLOSED = -1.0, 1.0   # gripper commands

def osc_position_controller(robot: str = "Panda") -> dict[str, Any]:
    """The robot's default composite controller with its arm swapped for OSC_POSITION + GRIP.

    OSC_POSITION keeps the gripper pointing down, which every scripted top-down grasp relies on;
    the action is 4-dimensional (dx, dy, dz, gripper).
    """
    config = load_composite_controller_config(robot=robot)
    arm = load_part_controller_config(default_controller="OSC_POSITION")
    arm["gripper"] = {"type": "GRIP"}
    config["body_parts"]["right"] = arm
    return config


def set_sampler_rng(sampler: ObjectPositionSampler, rng: np.random.Generator) -> None:
    """Point ``sampler`` (and, for a composite, every sub-sampler) at ``rng``."""
    sampler.rng = rng
    if isinstance(sampler, SequentialCompositeSampler):
        for sub in sampler.samplers.values():
            set_sampler_rng(sub, rng)


@dataclass(frozen=True)
class SubgoalKind:
    """A predicate family: its argument schema and its achievement / target functions.

    ``args`` maps an argument name to its type: ``"object"`` (a movable object of the task),
    ``"place"`` (an object or a fixed location), ``"location"`` or ``"float"``; ``defaults`` holds the
    optional ones. ``achieved(args, contacts) -> bool`` and ``target(args, contacts) -> (xyz, g)``.
    ``lasting``: the predicate is where an object rests, which a later option can change (a cube picked
    up again or pushed on), not a step on the way (where the hand is, what it holds) nor a state no
    option undoes (a ball in a bin); see :meth:`SubgoalManipulationEnv.subgoal_lasting`.
    """

    args: dict[str, str]
    achieved: Callable[[dict[str, Any], set], bool]
    target: Callable[[dict[str, Any], set], tuple[np.ndarray, float]]
    defaults: dict[str, Any] = field(default_factory=dict)
    lasting: bool = False


@dataclass(frozen=True)
class _Compiled:
    name: str
    kind: str
    args: dict[str, Any]


class SubgoalManipulationEnv(ManipulationEnv):
    """Base of the HUBS-GO arm tasks: Panda + OSC_POSITION on a table, sparse reward, sub-goals.

    Subclasses build their scene in ``_load_model`` (calling :meth:`_load_table` and filling
    ``self.objects`` / ``self.locations``) and implement ``_setup_references``,
    ``_reset_internal``, ``_setup_observables`` and ``_check_success``.

    Args:
        catalogue: the task's sub-goal catalogue (``envs/<task>.yaml``).
        robots: robosuite robot name.
        placement_initializer: a robosuite ``ObjectPositionSampler`` replacing the task's default
            one; it is re-seeded by :meth:`reseed` like the default.
        horizon: episode length in control steps (truncation is the Gymnasium wrapper's job).
        control_freq: control steps per simulated second.
        seed: seed of the task's ``np.random.Generator`` (object placement, joint noise).
        initialization_noise: robosuite's initial-joint noise spec.
        travel_clearance: height above the table at which targets route the end effector between
            distant points, so carried objects clear the others.
    """

    #: sub-goal tolerances (metres); comments say what each one decides
    reach_tolerance = 0.02      # reach_above: end effector within this of the hover point
    hover_height = 0.08         # default height of reach_above over the object centre
    xy_tolerance = 0.02         # beyond this horizontal error a target routes via travel height
    z_tolerance = 0.02          # "at travel height" slack
    grip_tolerance = 0.015      # close (grasp) / open (place) once this close to the grip point
    place_xy_tolerance = 0.025  # place_on: horizontal error of the object on its support
    place_z_tolerance = 0.012   # place_on: gap between object bottom and support top
    table_friction = (1.0, 5e-3, 1e-4)   # sliding, torsional, rolling (MuJoCo takes the max of a pair)

    def __init__(
        self,
        catalogue: Catalogue,
        robots: str = "Panda",
        placement_initializer: ObjectPositionSampler | None = None,
        horizon: int = DEFAULT_HORIZON,
        control_freq: int = 20,
        seed: int | None = None,
        initialization_noise: Any = "default",
        travel_clearance: float = 0.1,
        table_full_size: tuple[float, float, float] = (0.8, 0.8, 0.05),
    ):
        if not isinstance(catalogue, Catalogue):
            raise TypeError(f"catalogue must be a Catalogue (load_catalogue(path)), got {type(catalogue).__name__}")
        if horizon < 1:
            raise ValueError(f"horizon must be a positive number of control steps, got {horizon}")
        if travel_clearance <= 0:
            raise ValueError(f"travel_clearance must be > 0 metres, got {travel_clearance}")
        self.catalogue = catalogue
        self.table_full_size = tuple(table_full_size)
        self.table_offset = np.array((0.0, 0.0, 0.8))
        self.travel_clearance = float(travel_clearance)
        self.placement_initializer = placement_initializer
        self.objects: dict[str, MujocoObject] = {}
        self.locations: dict[str, str] = {}   # location name -> static body name (surface centre)
        super().__init__(
            robots=robots,
            controller_configs=osc_position_controller(robots),
            initialization_noise=initialization_noise,
            use_camera_obs=False,
            has_renderer=False,
            has_offscreen_renderer=False,
            control_freq=control_freq,
            horizon=horizon,
            ignore_done=True,            # the Gymnasium wrapper owns termination and truncation
            hard_reset=False,            # a hard reset rebuilds the model and takes seconds
            renderer="mujoco",           # no viewer object, nothing to update per step
            seed=seed,
        )
        self.reseed(seed)
        self._kinds = self._subgoal_kinds()
        self._subgoals = [self._compile(i, sg) for i, sg in enumerate(catalogue.subgoals)]

    # ------------------------------------------------------------------ seeding
    def reseed(self, seed: int | None) -> None:
        """Replace the task's generator; every sampler and the joint noise then draw from it."""
        self.rng = np.random.default_rng(seed)
        set_sampler_rng(self.placement_initializer, self.rng)

    # ------------------------------------------------------------------ scene helpers
    def _load_table(self) -> TableArena:
        """Place the robot at the table and return the arena (called first by ``_load_model``)."""
        super()._load_model()
        xpos = self.robots[0].robot_model.base_xpos_offset["table"](self.table_full_size[0])
        self.robots[0].robot_model.set_base_xpos(xpos)
        arena = TableArena(table_full_size=self.table_full_size, table_friction=self.table_friction,
                           table_offset=self.table_offset)
        arena.set_origin([0, 0, 0])
        return arena

    @property
    def table_top(self) -> float:
        return float(self.table_offset[2])

    def _add_static_box(self, arena: TableArena, name: str, pos, half_size, rgba, collide: bool = True) -> None:
        """A fixed box in the world (walls, bins, destination pads). Non-colliding boxes are markers."""
        body = new_body(name=name, pos=tuple(float(p) for p in pos))
        extra = {} if collide else {"contype": "0", "conaffinity": "0"}
        body.append(new_geom(name=f"{name}_g", type="box", size=tuple(half_size), rgba=tuple(rgba),
                             group=0 if collide else 1, **extra))
        arena.worldbody.append(body)

    def _add_location(self, arena: TableArena, name: str, xy, rgba, half_size=(0.04, 0.04)) -> None:
        """A flat coloured pad on the table, registered as location ``name`` (surface centre)."""
        thickness = 0.001
        self._add_static_box(arena, f"loc_{name}", (xy[0], xy[1], self.table_top + thickness),
                             (half_size[0], half_size[1], thickness), rgba, collide=False)
        self.locations[name] = f"loc_{name}"

    def _move_location(self, name: str, xy) -> None:
        """Move a pad between episodes (static bodies live in the model, not in qpos)."""
        body = self.sim.model.body_name2id(self.locations[name])
        self.sim.model.body_pos[body][:2] = xy

    def _setup_references(self):
        super()._setup_references()
        model = self.sim.model
        self._eef_site = self.robots[0].eef_site_id["right"]
        gripper = self.robots[0].gripper["right"]
        self._pad_geoms = [
            np.array([model.geom_name2id(g) for g in gripper.important_geoms[pad]])
            for pad in ("left_fingerpad", "right_fingerpad")
        ]
        self._object_body = {n: model.body_name2id(o.root_body) for n, o in self.objects.items()}
        self._object_geoms = {n: np.array([model.geom_name2id(g) for g in o.contact_geoms])
                              for n, o in self.objects.items()}
        self._location_body = {n: model.body_name2id(b) for n, b in self.locations.items()}

    def _reset_objects(self) -> None:
        """Draw object poses from the placement sampler (with this task's rng) and write them."""
        for pos, quat, obj in self.placement_initializer.sample().values():
            self.sim.data.set_joint_qpos(obj.joints[0], np.concatenate([np.array(pos), np.array(quat)]))

    def _observable(self, name: str, fn: Callable[[dict], np.ndarray]) -> tuple[str, Observable]:
        """An object-modality observable sampled once per control step."""
        fn.__name__ = name
        return name, Observable(name=name, sensor=sensor(modality="object")(fn), sampling_rate=self.control_freq)

    def _object_sensors(self, names: list[str], with_quat: bool) -> OrderedDict:
        """Position (and xyzw quaternion) observables of the named objects."""
        out = OrderedDict()
        for n in names:
            body = self._object_body[n]
            out.update([self._observable(f"{n}_pos", lambda cache, b=body: np.array(self.sim.data.body_xpos[b]))])
            if with_quat:
                out.update([self._observable(
                    f"{n}_quat", lambda cache, b=body: np.array(self.sim.data.body_xquat[b])[[1, 2, 3, 0]])])
        return out

    def _location_sensors(self, names: list[str]) -> OrderedDict:
        """Position observables of locations (pads move between episodes)."""
        return OrderedDict(self._observable(f"{n}_pos", lambda cache, b=self._location_body[n]:
                                            np.array(self.sim.data.body_xpos[b])) for n in names)

    def _eef_to_sensors(self, names: list[str]) -> OrderedDict:
        """Object position minus end-effector position, for each named object."""
        return OrderedDict(self._observable(f"eef_to_{n}", lambda cache, b=self._object_body[n]:
                                            np.array(self.sim.data.body_xpos[b]) - self.eef_position())
                           for n in names)

    #: proprioceptive observables that start every flat observation
    proprio_keys = ("robot0_eef_pos", "robot0_eef_quat", "robot0_gripper_qpos")

    @property
    def observation_keys(self) -> list[str]:
        """Keys of robosuite's observation dict, in the order the flat observation concatenates them."""
        return list(self.proprio_keys) + [k for k, o in self._observables.items()
                                          if o.modality == "object" and o.is_enabled()]

    # ------------------------------------------------------------------ state queries
    def eef_position(self) -> np.ndarray:
        """End-effector (grip site) position in the world frame, metres."""
        return np.array(self.sim.data.site_xpos[self._eef_site])

    def object_position(self, name: str) -> np.ndarray:
        return np.array(self.sim.data.body_xpos[self._object_body[name]])

    def place_top(self, name: str) -> np.ndarray:
        """Centre of the upper surface of an object or a location (what things are placed on)."""
        if name in self.objects:
            return self.object_position(name) + np.array(self.objects[name].top_offset)
        return np.array(self.sim.data.body_xpos[self._location_body[name]])

    def contacts(self) -> set[tuple[int, int]]:
        """Current contacts as sorted geom-id pairs (computed once per query, shared by predicates)."""
        n = self.sim.data.ncon
        c = self.sim.data._data.contact
        g1, g2 = c.geom1[:n], c.geom2[:n]
        return set(zip(np.minimum(g1, g2).tolist(), np.maximum(g1, g2).tolist()))

    def _touching(self, a: np.ndarray, b: np.ndarray, contacts: set) -> bool:
        return any((min(i, j), max(i, j)) in contacts for i in a.tolist() for j in b.tolist())

    def is_grasped(self, name: str, contacts: set | None = None) -> bool:
        """Both finger pads touch the object (robosuite's grasp test, on one shared contact set)."""
        contacts = self.contacts() if contacts is None else contacts
        geoms = self._object_geoms[name]
        return all(self._touching(pad, geoms, contacts) for pad in self._pad_geoms)

    def is_placed_on(self, name: str, support: str, contacts: set | None = None) -> bool:
        """Object ``name`` rests, released, centred on ``support`` (an object or a location)."""
        contacts = self.contacts() if contacts is None else contacts
        bottom = self.object_position(name) + np.array(self.objects[name].bottom_offset)
        top = self.place_top(support)
        return (np.linalg.norm(bottom[:2] - top[:2]) < self.place_xy_tolerance
                and abs(bottom[2] - top[2]) < self.place_z_tolerance
                and not self.is_grasped(name, contacts))

    # ------------------------------------------------------------------ routing
    def travel_height(self, start_xy: np.ndarray, goal_xy: np.ndarray) -> float:
        """Height at which the end effector may move horizontally from ``start_xy`` to ``goal_xy``."""
        return self.table_top + self.travel_clearance

    def _route(self, goal: np.ndarray) -> np.ndarray:
        """Next waypoint towards ``goal``: lift to travel height, cross, then descend onto it."""
        eef = self.eef_position()
        if np.linalg.norm(eef[:2] - goal[:2]) <= self.xy_tolerance:
            return goal
        z_travel = max(self.travel_height(eef[:2], goal[:2]), goal[2])
        if eef[2] < z_travel - self.z_tolerance:
            return np.array([eef[0], eef[1], z_travel])
        return np.array([goal[0], goal[1], z_travel])

    # ------------------------------------------------------------------ sub-goal kinds
    def _subgoal_kinds(self) -> dict[str, SubgoalKind]:
        """Kinds every arm task understands; subclasses add their own (``push_to``, ``collect``)."""
        return {
            "reach_above": SubgoalKind({"object": "object", "height": "float"}, self._reach_above_achieved,
                                       self._reach_above_target, defaults={"height": self.hover_height}),
            "grasp": SubgoalKind({"object": "object"}, self._grasp_achieved, self._grasp_target),
            "place_on": SubgoalKind({"object": "object", "onto": "place"}, self._place_on_achieved,
                                    self._place_on_target, lasting=True),
        }

    def _reach_above_point(self, args) -> np.ndarray:
        return self.object_position(args["object"]) + np.array([0.0, 0.0, args["height"]])

    def _reach_above_achieved(self, args, contacts) -> bool:
        return bool(np.linalg.norm(self.eef_position() - self._reach_above_point(args)) < self.reach_tolerance)

    def _reach_above_target(self, args, contacts):
        return self._route(self._reach_above_point(args)), OPEN

    def _grasp_achieved(self, args, contacts) -> bool:
        return self.is_grasped(args["object"], contacts)

    def _grasp_target(self, args, contacts):
        return self._pick(args["object"], contacts)

    def _pick(self, name: str, contacts) -> tuple[np.ndarray, float]:
        """Approach the object's centre open, close once there; hold still once grasped."""
        if self.is_grasped(name, contacts):
            return self.eef_position(), CLOSED
        goal = self.object_position(name)
        if np.linalg.norm(self.eef_position() - goal) < self.grip_tolerance:
            return goal, CLOSED
        return self._route(goal), OPEN

    def _place_on_achieved(self, args, contacts) -> bool:
        return self.is_placed_on(args["object"], args["onto"], contacts)

    def _place_on_target(self, args, contacts):
        """Pick the object up where it lies (as ``collect`` does), carry it over the support, open.

        A place option is complete on its own: not holding the object, its target is the pick, so a
        high level that chooses ``place_red_on_target`` first needs no separate grasp option, and an
        object dropped off-centre is picked up again."""
        name, support = args["object"], args["onto"]
        if not self.is_grasped(name, contacts):
            return self._pick(name, contacts)
        return self._carry_to(name, self.place_top(support), release_height=0.004)

    def _carry_to(self, name: str, surface: np.ndarray, release_height: float) -> tuple[np.ndarray, float]:
        """Carry a grasped object so its bottom is ``release_height`` above ``surface``; open there."""
        eef = self.eef_position()
        obj = self.object_position(name)
        obj_goal = surface - np.array(self.objects[name].bottom_offset) + np.array([0, 0, release_height])
        goal = obj_goal + (eef - obj)   # the grip offset the object has in the hand now
        if np.linalg.norm(eef - goal) < self.grip_tolerance:
            return goal, OPEN
        return self._route(goal), CLOSED

    # ------------------------------------------------------------------ sub-goal interface
    def _compile(self, index: int, sg: SubgoalDef) -> _Compiled:
        where = f"{self.catalogue.source}: subgoals[{index}] ({sg.name})"
        if sg.kind not in self._kinds:
            raise SpecError(f"{where}: kind {sg.kind!r} is not known to {type(self).__name__}; "
                            f"use one of: {', '.join(sorted(self._kinds))}")
        kind = self._kinds[sg.kind]
        unknown = set(sg.args) - set(kind.args)
        if unknown:
            raise SpecError(f"{where}: args: unknown key(s) {sorted(unknown)} for kind {sg.kind!r}; "
                            f"allowed: {', '.join(kind.args)}")
        args = dict(kind.defaults)
        args.update(sg.args)
        for key, typ in kind.args.items():
            if key not in args:
                raise SpecError(f"{where}: args.{key}: required for kind {sg.kind!r}; add it")
            args[key] = self._check_arg(where, key, typ, args[key])
        for key, typ in kind.args.items():     # an object cannot be put on, or moved to, itself
            if typ == "place" and "object" in args and args[key] == args["object"]:
                others = [p for p in self._choices(typ) if p != args["object"]]
                raise SpecError(f"{where}: args.{key}: {args[key]!r} is the object itself; name another "
                                f"place of {type(self).__name__}: {', '.join(others)}")
        return _Compiled(sg.name, sg.kind, args)

    def _choices(self, typ: str) -> list[str] | None:
        """The names an argument of type ``typ`` may take (None: a number)."""
        return {"object": list(self.objects), "location": list(self.locations),
                "place": list(self.objects) + list(self.locations)}.get(typ)

    def _check_arg(self, where: str, key: str, typ: str, value: Any) -> Any:
        choices = self._choices(typ)
        if choices is None:
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise SpecError(f"{where}: args.{key}: expected a number, got {value!r}")
            if value < 0:   # a height below the object puts the target inside the table or the object
                raise SpecError(f"{where}: args.{key}: {value!r} is below the object; give 0 or more metres")
            return float(value)
        if value not in choices:
            raise SpecError(f"{where}: args.{key}: {value!r} is not {'an' if typ[0] in 'aeiou' else 'a'} {typ} "
                            f"of {type(self).__name__}; use one of: {', '.join(choices)}")
        return value

    @property
    def subgoal_names(self) -> list[str]:
        return [sg.name for sg in self._subgoals]

    def subgoal_achieved(self) -> np.ndarray:
        """Achievement of every catalogue sub-goal on the current state, ``bool`` array (N,)."""
        contacts = self.contacts()
        return np.array([self._kinds[sg.kind].achieved(sg.args, contacts) for sg in self._subgoals], dtype=bool)

    def subgoal_lasting(self) -> np.ndarray:
        """Which sub-goals are lasting states of the scene (``SubgoalKind.lasting``), ``bool`` array (N,).
        A successful episode is evidence for such a sub-goal only where it still holds at the success:
        a cube placed on one pad and then moved to another was not placed on the first in the end."""
        return np.array([self._kinds[sg.kind].lasting for sg in self._subgoals], dtype=bool)

    def subgoal_target(self, index: int) -> tuple[np.ndarray, float]:
        """Target of sub-goal ``index`` on the current state: (end-effector xyz, gripper in [-1, 1])."""
        if not 0 <= index < len(self._subgoals):
            raise IndexError(f"sub-goal index {index} out of range; this task has {len(self._subgoals)} "
                             f"sub-goals: {', '.join(self.subgoal_names)}")
        sg = self._subgoals[index]
        xyz, gripper = self._kinds[sg.kind].target(sg.args, self.contacts())
        return np.asarray(xyz, dtype=np.float64), float(gripper)

    # ------------------------------------------------------------------ reward
    def reward(self, action=None) -> float:
        """Sparse reward of the paper's tasks (Sec. 4): 1 on success, else 0."""
        return 1.0 if self._check_success() else 0.0
