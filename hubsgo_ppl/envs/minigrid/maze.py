"""MazeEnv: one MiniGrid environment built from a sub-goal catalogue and an ASCII layout.

## Description

A grid maze declared without Python: ``envs/<task>.yaml`` (a sub-goal catalogue with
``family: minigrid``) names an ASCII layout (``envs/<task>.txt``) and a legend. The agent must reach
the green goal square; keys open locked doors of their colour. The candidate sub-goals G0 of
HUBS-GO (paper Sec. 3) are the catalogue's named predicates; the env reports which hold after every
step. See :mod:`hubsgo_ppl.envs.minigrid.layout` for the ASCII legend and the ``options`` keys::

    #  wall     .  floor     A  agent start     G  goal     ~  lava
    other characters: options.legend, e.g. y: {type: key, color: yellow},
                                          Y: {type: door, color: yellow, locked: true}

## Action Space

``Discrete(len(options.actions))``: a subset of MiniGrid's actions, in the catalogue's order.
Default ``[left, right, forward, pickup, toggle]``:

| Num | Name    | Action                          |
|-----|---------|---------------------------------|
| 0   | left    | turn left                       |
| 1   | right   | turn right                      |
| 2   | forward | move forward                    |
| 3   | pickup  | pick up the object in front     |
| 4   | toggle  | open/close (unlock) the door in front |

``actions: [east, south, west, north]`` (the cardinal set, :mod:`.cardinal`): each action moves one
cell that way, picking up a key or ball and opening a door (locked: with its key in hand) on contact.

## Observation

A flat ``Box`` of float32, so CPU training is fast (``obs_mode: symbolic``, the default), laid out as
``[one-hot x (W) | one-hot y (H) | one-hot direction (4) | one-hot carried (1 + K) | door open (D)]``
where K is the number of distinct (type, colour) carriable objects in the layout (slot 0 = nothing)
and D the number of doors in reading order. ``obs_mode: image`` gives MiniGrid's full-grid encoding
(object, colour, state per cell, the agent's cell as (agent, red, direction)) flattened to
``W*H*3`` floats in [0, 255].

``obs_mode: egocentric`` describes the maze as the agent sees it, with no absolute position or
heading, so that what a policy learns on one layout applies to the same task with its walls and
objects moved or turned (``hubsgo train --init-from``)::

    [carrying anything (1) | achieved (L) | offset (2L) | window (2 * 7 * 7)]

over the catalogue's L sub-goals (all of them, even when a critic spec keeps only some, so that a
revision keeps the observation's shape): whether each holds, and the offset from the agent to its
target (``subgoal_target``) in the agent's frame, (ahead, to the right) over ``max(W, H)``. The
window is the 7x7 cells around the agent, turned so that the agent faces up it: channel 0 is 1 where
the agent cannot step (a wall, a closed door, a key or ball on the floor, outside the grid), channel 1
where there is lava. Floats in [-1, 1]. Two tasks' observations mean the same when their catalogues
list the same sub-goals in the same order. :mod:`hubsgo_ppl.envs.minigrid.egocentric` builds it.

## Rewards

Sparse, as in the paper (Sec. 4): MiniGrid's ``1 - 0.9 * (step_count / max_steps)`` on reaching the
goal, 0 otherwise (also 0 on lava). The discount by elapsed steps keeps the optimum unique; the
undiscounted "1 on success" reading is ``info["is_success"]``.

## Termination

Terminated when the agent steps on the goal (``is_success``) or on lava; truncated at ``max_steps``.

## Sub-goals (the contract of docs/design.md)

``env.unwrapped.subgoal_names``, ``subgoal_achieved() -> ndarray[bool] (N,)`` on the current state,
``subgoal_target(i) -> (x, y)`` (the cell to reach, or the key/door to face), and
``info["subgoals"]`` / ``info["is_success"]`` after ``reset`` and every ``step``.

## Registered Configurations

- ``hubsgo/KeyDoor-v0`` (``keydoor``): 13x13, a wall at x=8 with a locked yellow door (8,4) and a
  locked blue door (8,8); a yellow key at (4,3), a blue key at (4,9); start (1,6) facing right, goal
  (11,6); ``max_steps`` 2000. Either key-door pair opens a route. Optimal: 19 steps (BFS).
  Sub-goals: ``yellow_key`` (carrying the yellow key), ``yellow_door`` (yellow door open),
  ``blue_key``, ``blue_door``, ``goal`` (agent on the goal).
- ``hubsgo/FourRoom-v0`` (``fourroom``): 13x13, four rooms split by walls at x=6 and y=6, doorways
  (6,3) ``door_top`` (TL-TR), (3,6) ``door_left`` (TL-BL), (9,6) ``door_right`` (TR-BR),
  (6,9) ``door_bottom`` (BL-BR); start (1,1) with a random direction (seeded), goal (11,11);
  ``max_steps`` 1000. Routes {door_top, door_right} and {door_left, door_bottom}; optimal 23 steps
  facing right/down, 24 facing left/up. Sub-goals: the four ``at`` doorways and ``goal``.
- ``hubsgo/KeyDoorIncorrect-v0``, ``hubsgo/FourRoomIncorrect-v0`` (paper Fig. 8): the same tasks with
  four misleading ``at`` sub-goals ``corner_*`` in room corners off both routes, after the correct ones.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from minigrid.core.actions import Actions
from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX
from minigrid.core.grid import Grid
from minigrid.core.mission import MissionSpace
from minigrid.core.world_object import Ball, Door, Goal, Key, Lava, Wall
from minigrid.minigrid_env import MiniGridEnv

from ...specs import SpecError
from ..subgoals import Catalogue
from . import cardinal, egocentric, image
from .layout import DIRECTIONS, MazeSpec, MazeState, load_maze_spec

__all__ = ["MazeEnv"]

_KIND_CODE = {"at": 0, "goal": 0, "carrying": 1, "door_open": 2}

def _compiled(predicates) -> tuple[tuple[int, tuple[int, int], int], ...]:
    return tuple((_KIND_CODE[p.kind], p.target, p.index) for p in predicates)


class MazeEnv(MiniGridEnv):
    """A MiniGrid maze declared by a catalogue YAML + ASCII layout (see the module docstring).

    Args:
        catalogue: path to the task's catalogue YAML (or a loaded :class:`Catalogue`).
        obs_mode: ``"symbolic"``, ``"image"`` or ``"egocentric"``; overrides ``options.obs_mode``.
        max_steps: overrides ``options.max_steps``.
        start: ``"cell"`` or ``"room"``; overrides ``options.start`` (``room``: each episode starts on a
            free cell of the start's room, drawn by the seeded reset, so that the low level meets its
            sub-goals from many places, e.g. in a run meant to be transferred).
        render_mode: ``None``, ``"rgb_array"`` or ``"human"`` (MiniGrid's renderer).
        **kwargs: passed to :class:`MiniGridEnv` (``tile_size``, ``screen_size``, ...).
    """

    def __init__(self, catalogue: str | Path | Catalogue, obs_mode: str | None = None,
                 max_steps: int | None = None, render_mode: str | None = None, start: str | None = None,
                 **kwargs: Any):
        spec = load_maze_spec(catalogue)
        if start is not None and start not in ("cell", "room"):
            raise SpecError(f"{spec.source}: start={start!r} is not supported; use 'cell' or 'room'")
        if obs_mode is not None and obs_mode not in ("symbolic", "image", "egocentric"):
            raise SpecError(f"{spec.source}: obs_mode={obs_mode!r} is not supported; use 'symbolic', 'image' "
                            f"or 'egocentric'")
        if max_steps is not None and (not isinstance(max_steps, int) or max_steps <= 0):
            raise SpecError(f"{spec.source}: max_steps={max_steps!r} must be a positive int")
        self.spec_maze: MazeSpec = spec
        lay = spec.layout
        super().__init__(mission_space=MissionSpace(mission_func=self._gen_mission),
                         width=lay.width, height=lay.height,
                         # the egocentric view is never observed; skipping occlusion keeps renders cheap
                         max_steps=max_steps or spec.max_steps, see_through_walls=True,
                         render_mode=render_mode, **kwargs)
        self.mission = spec.options.mission
        self.obs_mode = obs_mode or spec.options.obs_mode
        # the cells an episode may start on: the layout's A, or every free cell of A's room
        self._starts = lay.start_room() if (start or spec.options.start) == "room" else (lay.agent_start,)
        self._cardinal = cardinal.is_cardinal(spec.options.actions)
        self._action_map = tuple(cardinal.CARDINAL[a] if self._cardinal else Actions[a] for a in spec.options.actions)
        self.action_space = spaces.Discrete(len(self._action_map))
        self.action_names = list(spec.options.actions)

        W, H = lay.width, lay.height
        self._off_y = W
        self._off_dir = W + H
        self._off_carry = W + H + 4
        self._carry_index = {kind: j + 1 for j, kind in enumerate(spec.carry_kinds)}
        self._off_door = self._off_carry + 1 + len(spec.carry_kinds)
        self._obs_dim = self._off_door + len(lay.doors)
        n_marks = len(spec.landmarks)
        self._ego_dim = egocentric.dim(n_marks)
        if self.obs_mode == "symbolic":
            self.observation_space = spaces.Box(0.0, 1.0, (self._obs_dim,), np.float32)
        elif self.obs_mode == "egocentric":
            self.observation_space = spaces.Box(-1.0, 1.0, (self._ego_dim,), np.float32)
        else:
            self.observation_space = spaces.Box(0.0, 255.0, (W * H * 3,), np.float32)

        # (kind code, target, index) per sub-goal; tuples so the per-step test is a tight loop
        self._preds = _compiled(spec.predicates)
        self._marks = _compiled(spec.landmarks)     # the egocentric observation's, over the whole catalogue
        self.subgoal_names: list[str] = spec.subgoal_names
        self._goal = lay.goal
        self._doors: list[Door] = []
        self._carriables: list[Key | Ball] = []

    @staticmethod
    def _gen_mission() -> str:
        return "reach the goal"

    # -- MiniGrid hooks -------------------------------------------------------------------------

    def _gen_grid(self, width: int, height: int) -> None:
        lay = self.spec_maze.layout
        self.grid = Grid(width, height)
        for x, y in lay.walls:
            self.grid.set(x, y, Wall())
        for x, y in lay.lava:
            self.grid.set(x, y, Lava())
        self.put_obj(Goal(), *lay.goal)
        if self.obs_mode == "image":
            # static cells never change, so encode them once per reset and patch the movable ones
            self._img_static = self.grid.encode()
        if self.obs_mode == "egocentric":
            # walls and lava never move: one padded map per reset, the doors and objects patched per step
            self._static = egocentric.static_map(lay)
        self._doors, self._carriables = [], []
        for o in lay.objects:
            if o.type == "door":
                obj = Door(o.color, is_open=o.open, is_locked=o.locked)
                self._doors.append(obj)
            else:
                obj = Key(o.color) if o.type == "key" else Ball(o.color)
                self._carriables.append(obj)
            self.put_obj(obj, *o.cell)
        sd = self.spec_maze.options.start_dir
        # the randomness a catalogue can ask for (start_dir: random, start: room); drawn from MiniGrid's
        # seeded np_random
        self.agent_dir = int(self.np_random.integers(0, 4)) if sd == "random" else DIRECTIONS[sd]
        # one start cell: no draw, so a catalogue without start: room keeps its random stream
        self.agent_pos = (self._starts[0] if len(self._starts) == 1
                          else self._starts[int(self.np_random.integers(len(self._starts)))])
        self.mission = self.spec_maze.options.mission

    def gen_obs(self) -> np.ndarray:
        """The flat observation (replaces MiniGrid's own egocentric view, which we never use)."""
        if self.obs_mode == "egocentric":
            return egocentric.observe(self)
        if self.obs_mode == "image":
            img = self._img_static.copy()
            for d in self._doors:
                img[d.cur_pos[0], d.cur_pos[1]] = d.encode()
            for obj in self._carriables:
                if obj is not self.carrying:
                    img[obj.cur_pos[0], obj.cur_pos[1]] = obj.encode()
            x, y = self.agent_pos
            img[x, y] = (OBJECT_TO_IDX["agent"], COLOR_TO_IDX["red"], self.agent_dir)
            return img.reshape(-1).astype(np.float32)
        obs = np.zeros(self._obs_dim, np.float32)
        x, y = self.agent_pos
        obs[x] = 1.0
        obs[self._off_y + y] = 1.0
        obs[self._off_dir + self.agent_dir] = 1.0
        c = self.carrying
        obs[self._off_carry + (0 if c is None else self._carry_index[(c.type, c.color)])] = 1.0
        for j, d in enumerate(self._doors):
            if d.is_open:
                obs[self._off_door + j] = 1.0
        return obs

    # -- Gymnasium API ----------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, _ = super().reset(seed=seed, options=options)
        return obs, {"subgoals": self.subgoal_achieved(), "is_success": False}

    def step(self, action):
        a = int(action)
        if not 0 <= a < len(self._action_map):
            raise ValueError(f"action {action!r} is outside Discrete({len(self._action_map)}); "
                             f"actions are {self.action_names}")
        act = cardinal.env_action(self, self._action_map[a]) if self._cardinal else self._action_map[a]
        obs, reward, terminated, truncated, _ = super().step(act)
        achieved = self.subgoal_achieved()
        success = bool(terminated) and self._agent_cell() == self._goal
        return obs, float(reward), bool(terminated), bool(truncated), {"subgoals": achieved,
                                                                      "is_success": success}

    # -- sub-goal contract (docs/design.md) -------------------------------------------------------

    def _agent_cell(self) -> tuple[int, int]:
        x, y = self.agent_pos
        return int(x), int(y)

    def subgoal_achieved(self) -> np.ndarray:
        """Which catalogue predicates hold in the current state: bool array (N,)."""
        return self._achieved(self._preds)

    def _achieved(self, preds: tuple) -> np.ndarray:
        out = np.zeros(len(preds), dtype=bool)
        pos = self._agent_cell()
        c = self.carrying
        carried = 0 if c is None else self._carry_index[(c.type, c.color)]
        for i, (code, target, idx) in enumerate(preds):
            if code == 0:
                out[i] = pos == target
            elif code == 1:
                out[i] = carried == idx + 1
            else:
                out[i] = self._doors[idx].is_open
        return out

    def subgoal_target(self, i: int) -> tuple[int, int]:
        """The cell the low level should reach (``at``/``goal``) or face (a key or a door)."""
        if not 0 <= int(i) < len(self._preds):
            raise IndexError(f"sub-goal index {i} out of range; this task has {len(self._preds)}: "
                             f"{self.subgoal_names}")
        return self._target(self._preds[int(i)])

    def _target(self, pred: tuple) -> tuple[int, int]:
        code, target, idx = pred
        if code == 1 and self._carriables:
            # a dropped key has moved; aim at where it lies now (or stay put while it is carried)
            kind = self.spec_maze.carry_kinds[idx]
            for obj in self._carriables:
                if (obj.type, obj.color) == kind:
                    if obj is self.carrying:
                        return self._agent_cell()
                    if obj.cur_pos is not None and obj.cur_pos[0] >= 0:
                        return int(obj.cur_pos[0]), int(obj.cur_pos[1])
        return target

    def subgoal_potential(self):
        """phi(obs) -> (B, N): minus the Manhattan distance from the agent's cell to each sub-goal's
        catalogue target, over (width + height); read from the observation of any ``obs_mode`` (an image
        observation's agent cell is where it holds the type ``agent``, :mod:`.image`).

        The low level may use it for potential-based shaping (Ng et al. 1999), which leaves its optimal
        policies unchanged; walls are not taken into account (the layout stays the learner's to discover).
        """
        if self.obs_mode == "egocentric":
            return egocentric.potential(self)
        W, H = self.grid.width, self.grid.height
        if self.obs_mode == "image":
            return image.fixed_potential(W, H, [target for _, target, _ in self._preds])
        import torch

        targets = torch.tensor([target for _, target, _ in self._preds], dtype=torch.float32)   # (N, 2)
        off_y, scale = self._off_y, float(W + H)

        def phi(obs: "torch.Tensor") -> "torch.Tensor":
            x = obs[..., :W].argmax(-1).float()
            y = obs[..., off_y:off_y + H].argmax(-1).float()
            d = (x[..., None] - targets[:, 0]).abs() + (y[..., None] - targets[:, 1]).abs()
            return -d / scale

        return phi

    def symbolic_state(self) -> MazeState:
        """The hashable full state (position, direction, carried object, object cells, door states)."""
        carrying = -1
        objects = []
        for j, obj in enumerate(self._carriables):
            if obj is self.carrying:
                carrying = j
                objects.append(None)
            else:
                objects.append((int(obj.cur_pos[0]), int(obj.cur_pos[1])))
        doors = tuple(2 if d.is_open else (0 if d.is_locked else 1) for d in self._doors)
        return MazeState(self._agent_cell(), int(self.agent_dir), carrying, tuple(objects), doors)
