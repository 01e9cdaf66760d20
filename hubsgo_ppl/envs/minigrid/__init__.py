"""MiniGrid tasks declared by a catalogue YAML + ASCII layout (``envs/*.yaml`` with family minigrid).

Importing this package registers nothing; call :func:`hubsgo_ppl.envs.register` (MiniGrid #455).
"""

from .bfs import optimal_return, optimal_steps, plan
from .layout import Layout, MazeSpec, MazeState, load_maze_spec, parse_layout
from .maze import MazeEnv

__all__ = ["MazeEnv", "MazeSpec", "MazeState", "Layout", "load_maze_spec", "parse_layout", "plan",
           "optimal_steps", "optimal_return"]
