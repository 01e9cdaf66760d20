"""MiniGrid tasks declared by a catalogue YAML (``envs/*.yaml`` with family minigrid): an ASCII layout
(:class:`MazeEnv`) or a registered MiniGrid id whose layout changes at every reset (:class:`RegisteredEnv`).

Importing this package registers nothing; call :func:`hubsgo_ppl.envs.register` (MiniGrid #455).
"""

from .bfs import optimal_return, optimal_steps, plan
from .layout import Layout, MazeSpec, MazeState, load_maze_spec, parse_layout
from .maze import MazeEnv
from .registered import RegisteredEnv, make_minigrid

__all__ = ["MazeEnv", "RegisteredEnv", "make_minigrid", "MazeSpec", "MazeState", "Layout", "load_maze_spec",
           "parse_layout", "plan", "optimal_steps", "optimal_return"]
