"""A small Gymnasium env of one's own, with its sub-goals written as Python predicates.

A corridor of cells 0..12; the agent starts in cell 6, 7 or 8. The goal at the right end (cell 12)
opens only once switch A (cell 3) is pressed; switch B, at the left end (cell 0), opens nothing.
Actions: left, right, press (a switch under the agent turns on and stays on). Reward 1 on reaching
the open goal, which ends the episode. The observation is the agent's position and the two switches.

``own_env.py`` trains HUBS-GO on it; the run's catalogue names ``corridor_env:make_corridor`` and
``corridor_env:switch_on``, so this file's folder must be importable (on ``PYTHONPATH``) for the
``hubsgo`` commands that read the run.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np

LENGTH = 13
SWITCHES = {"a": 3, "b": 0}
LEFT, RIGHT, PRESS = 0, 1, 2


class Corridor(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(self, length: int = LENGTH, render_mode: str | None = None):
        self.length = int(length)
        self.render_mode = render_mode
        self.observation_space = gym.spaces.Box(0.0, 1.0, (3,), np.float32)
        self.action_space = gym.spaces.Discrete(3)
        self.pos = 0
        self.switches = {"a": False, "b": False}

    def _obs(self) -> np.ndarray:
        return np.array([self.pos / (self.length - 1), self.switches["a"], self.switches["b"]], dtype=np.float32)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.pos = int(self.np_random.integers(6, 9))       # seeded by reset(seed)
        self.switches = {"a": False, "b": False}
        return self._obs(), {}

    def step(self, action):
        if action == LEFT:
            self.pos = max(self.pos - 1, 0)
        elif action == RIGHT:
            # the goal cell is closed until switch A is on
            self.pos = min(self.pos + 1, self.length - 1 if self.switches["a"] else self.length - 2)
        else:
            for name, cell in SWITCHES.items():
                if self.pos == cell:
                    self.switches[name] = True
        solved = self.pos == self.length - 1
        return self._obs(), float(solved), solved, False, {}

    def render(self):
        """One row of 16-pixel cells: grey floor, switches yellow (off) or green (on), goal blue, agent red."""
        row = np.full((16, 16 * self.length, 3), 96, np.uint8)
        for name, cell in SWITCHES.items():
            row[:, 16 * cell:16 * cell + 16] = (40, 200, 40) if self.switches[name] else (220, 200, 40)
        row[:, -16:] = (40, 80, 220)
        row[4:12, 16 * self.pos + 4:16 * self.pos + 12] = (220, 40, 40)
        return row


def make_corridor(**kwargs) -> Corridor:
    """The env factory a catalogue names (``entry_point: corridor_env:make_corridor``)."""
    return Corridor(**kwargs)


def switch_on(env: Corridor, obs, info, which: str) -> bool:
    """Sub-goal predicate: switch ``which`` is on (``env`` is the Corridor itself)."""
    return bool(env.switches[which])
