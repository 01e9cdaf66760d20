"""What the low level reads from an ``obs_mode: image`` observation: the shaping potential.

An image observation is MiniGrid's full-grid encoding flattened, ``W * H * 3`` floats indexed
``(x * H + y) * 3 + channel``; channel 0 is the object's type (``OBJECT_TO_IDX``), 1 its colour, 2 its
state (a door: 0 open, 1 closed, 2 locked). The agent's cell holds the type ``agent``, so its position is
read from the image itself, and the potential is the one of the other modes: minus the Manhattan
distance from the agent's cell to each sub-goal's target, over (width + height).

* :func:`fixed_potential` takes the targets as given (a maze's catalogue targets, as its symbolic
  potential does);
* :func:`scene_potential` reads each target from the image as the egocentric observation's offsets
  do (a registered environment, whose layout changes at every reset): the nearest object the
  sub-goal's arguments select (a door: a closed one first), a fixed ``cell`` as given, and the agent's
  own cell where no such object is on the floor (it is carried, or the agent stands on it). The
  ``goal`` of an environment without a goal square is the nearest object of the type its mission
  names (``"open the door"``: a door). A target the image does not show by itself (a box's contents,
  a mission's cell) is taken as the nearest object of the named type and colour, else the agent's
  cell, where that sub-goal is not shaped.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Sequence

from minigrid.core.constants import COLOR_TO_IDX, OBJECT_TO_IDX

if TYPE_CHECKING:
    import torch

__all__ = ["agent_cells", "fixed_potential", "scene_potential"]

_AGENT = OBJECT_TO_IDX["agent"]
_CARRIABLE = ("key", "ball", "box")


def agent_cells(obs: "torch.Tensor", width: int, height: int) -> tuple["torch.Tensor", "torch.Tensor"]:
    """The agent's (x, y) in each image observation of a ``width`` x ``height`` grid, as floats."""
    kinds = obs.reshape(*obs.shape[:-1], width * height, 3)[..., 0]
    idx = (kinds == _AGENT).float().argmax(-1)
    return (idx // height).float(), (idx % height).float()


def fixed_potential(width: int, height: int, targets: Sequence[tuple[int, int]]
                    ) -> Callable[["torch.Tensor"], "torch.Tensor"]:
    """phi(obs) -> (..., N): minus the Manhattan distance from the agent's cell to each of ``targets``."""
    import torch

    cells = torch.tensor([tuple(t) for t in targets], dtype=torch.float32)       # (N, 2)
    scale = float(width + height)

    def phi(obs: torch.Tensor) -> torch.Tensor:
        x, y = agent_cells(obs, width, height)
        d = (x[..., None] - cells[:, 0]).abs() + (y[..., None] - cells[:, 1]).abs()
        return -d / scale

    return phi


def _selector(kind: str, args: Any) -> tuple[tuple[int, ...], int | None, tuple[int, int] | None]:
    """(the types, the colour or None, a fixed cell or None) a sub-goal's target is read from."""
    if kind == "at" and getattr(args, "cell", None) is not None:
        return (), None, tuple(args.cell)
    if kind == "goal":
        return (OBJECT_TO_IDX["goal"],), None, None
    named = getattr(args, "type", None)
    types = (named,) if named else (_CARRIABLE if kind in ("carrying", "placed_near", "cleared") else
                                    tuple(t for t in OBJECT_TO_IDX if t not in ("agent", "unseen", "empty", "wall",
                                                                                   "floor")))
    colour = getattr(args, "color", None)
    return tuple(OBJECT_TO_IDX[t] for t in types), (COLOR_TO_IDX[colour] if colour else None), None


def scene_potential(width: int, height: int, kinds: Sequence[tuple[str, Any]], mission_type: str | None = None
                    ) -> Callable[["torch.Tensor"], "torch.Tensor"]:
    """phi(obs) -> (..., N) for sub-goals given as (kind, validated args), each target read from the
    image (see the module docstring); ``mission_type``, the type of object the mission names (the
    ``goal``'s target where there is no goal square)."""
    import torch

    xs = torch.arange(width, dtype=torch.float32)[:, None].expand(width, height)
    ys = torch.arange(height, dtype=torch.float32)[None, :].expand(width, height)
    picks = [_selector(kind, args) for kind, args in kinds]
    goal_code, named_code = OBJECT_TO_IDX["goal"], OBJECT_TO_IDX.get(mission_type or "", None)
    doors = [kind == "door_open" for kind, _ in kinds]
    scale = float(width + height)
    far = float(width + height + 1)

    def phi(obs: torch.Tensor) -> torch.Tensor:
        img = obs.reshape(*obs.shape[:-1], width, height, 3)
        types, colours, states = img[..., 0], img[..., 1], img[..., 2]
        ax, ay = agent_cells(obs, width, height)
        dist = (xs - ax[..., None, None]).abs() + (ys - ay[..., None, None]).abs()       # (..., W, H)
        out = []
        for (codes, colour, cell), door in zip(picks, doors):
            if cell is not None:
                out.append((ax - cell[0]).abs() + (ay - cell[1]).abs())
                continue
            match = torch.zeros_like(types, dtype=torch.bool)
            for code in codes:
                match |= types == code
            if colour is not None:
                match &= colours == colour
            d = torch.where(match, dist, torch.full_like(dist, far)).flatten(-2).amin(-1)
            if codes == (goal_code,) and named_code is not None:     # no goal square: the mission's object
                named = torch.where(types == named_code, dist, torch.full_like(dist, far)).flatten(-2).amin(-1)
                d = torch.where(d < far, d, named)
            if door:            # a closed door first, as the low level's target is
                shut = torch.where(match & (states > 0), dist, torch.full_like(dist, far)).flatten(-2).amin(-1)
                d = torch.where(shut < far, shut, d)
            out.append(torch.where(d < far, d, torch.zeros_like(d)))
        return -torch.stack(out, -1) / scale

    return phi
