"""The egocentric observation of a maze (``obs_mode: egocentric``) and what the low level reads from it.

The observation describes the maze as the agent sees it, with no absolute position or heading::

    [carrying anything (1) | achieved (L) | offset (2L) | window (2 * VIEW * VIEW)]

over the catalogue's L landmarks (see :class:`~hubsgo_ppl.envs.minigrid.maze.MazeEnv`). Besides it,
this module builds the low level's readers of such an observation: the shaping potential
(:func:`potential`) and the per-sub-goal features of a goal-conditioned low level (:func:`features`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .layout import Layout

if TYPE_CHECKING:
    import torch

__all__ = ["VIEW", "dim", "static_map", "observe", "potential", "features"]

#: the egocentric window's side, in cells (the agent in its centre)
VIEW = 7
#: MiniGrid's direction -> the unit step forward (0 right, 1 down, 2 left, 3 up; y grows downwards)
_FORWARD = ((1, 0), (0, 1), (-1, 0), (0, -1))


def _window_offsets(direction: int) -> tuple[np.ndarray, np.ndarray]:
    """World (dx, dy) of each window cell, row by row from the farthest ahead, left to right as the
    agent facing ``direction`` sees them; so every heading gives the same window for the same view."""
    fx, fy = _FORWARD[direction]
    rx, ry = -fy, fx                                  # the agent's right
    r = VIEW // 2
    ahead, right = np.meshgrid(np.arange(r, -r - 1, -1), np.arange(-r, r + 1), indexing="ij")
    return (ahead * fx + right * rx).reshape(-1), (ahead * fy + right * ry).reshape(-1)


_WINDOW = tuple(_window_offsets(d) for d in range(4))


def dim(n_marks: int) -> int:
    """The observation's length over ``n_marks`` landmarks."""
    return 1 + 3 * n_marks + 2 * VIEW * VIEW


def static_map(lay: Layout) -> np.ndarray:
    """The cells that never change, padded by half a window: channel 0 is 1 on walls and outside the
    grid, channel 1 on lava. Built once per reset; :func:`observe` patches in the doors and objects."""
    pad = VIEW // 2
    width, height = lay.width, lay.height
    static = np.ones((2, width + 2 * pad, height + 2 * pad), np.float32)
    static[1] = 0.0
    static[0, pad:pad + width, pad:pad + height] = 0.0
    for x, y in lay.walls:
        static[0, x + pad, y + pad] = 1.0
    for x, y in lay.lava:
        static[1, x + pad, y + pad] = 1.0
    return static


def compose(dim: int, carrying: bool, achieved: np.ndarray, agent: tuple[int, int], direction: int,
            targets: list[tuple[int, int]], scale: float, grid: np.ndarray) -> np.ndarray:
    """The egocentric vector (module docstring) from its parts: ``grid`` is the padded (2, W+6, H+6)
    blocked/lava map, ``targets`` the sub-goals' target cells, ``scale`` max(W, H)."""
    n = len(targets)
    obs = np.zeros(dim, np.float32)
    obs[0] = float(carrying)
    obs[1:1 + n] = achieved
    ax, ay = agent
    fx, fy = _FORWARD[direction]
    for i, (tx, ty) in enumerate(targets):
        dx, dy = tx - ax, ty - ay
        # ahead = d . forward; right = d . (the forward vector turned clockwise on screen, y down)
        obs[1 + n + 2 * i] = (dx * fx + dy * fy) / scale
        obs[2 + n + 2 * i] = (-dx * fy + dy * fx) / scale
    pad = VIEW // 2
    wx, wy = _WINDOW[direction]
    obs[1 + 3 * n:] = grid[:, wx + ax + pad, wy + ay + pad].reshape(-1)
    return obs


def observe(env: Any) -> np.ndarray:
    """The egocentric observation of ``env`` (a :class:`~hubsgo_ppl.envs.minigrid.maze.MazeEnv`)."""
    grid = env._static.copy()
    pad = VIEW // 2
    for d in env._doors:
        if not d.is_open:
            grid[0, d.cur_pos[0] + pad, d.cur_pos[1] + pad] = 1.0
    for obj in env._carriables:
        if obj is not env.carrying and obj.cur_pos is not None and obj.cur_pos[0] >= 0:
            grid[0, obj.cur_pos[0] + pad, obj.cur_pos[1] + pad] = 1.0
    marks = env._marks
    return compose(env._ego_dim, env.carrying is not None, env._achieved(marks), env._agent_cell(),
                   env.agent_dir, [env._target(pred) for pred in marks], float(max(env.width, env.height)), grid)


def potential(env: Any) -> Callable[[torch.Tensor], torch.Tensor]:
    """phi for egocentric observations: minus the Manhattan distance to each sub-goal's target over
    (width + height), as the symbolic potential, read from the offsets (to where each target is now: a
    carried key's is the agent's own cell)."""
    import torch

    marks = [p.name for p in env.spec_maze.landmarks]
    n = len(marks)
    cols = torch.tensor([1 + n + 2 * marks.index(name) for name in env.subgoal_names])
    scale = float(max(env.width, env.height)) / float(env.width + env.height)

    def phi(obs: torch.Tensor) -> torch.Tensor:
        return -(obs[..., cols].abs() + obs[..., cols + 1].abs()) * scale

    return phi
