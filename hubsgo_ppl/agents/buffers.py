"""Replay buffers: fixed-size numpy ring buffers with an explicit generator and a state_dict for resume."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

__all__ = ["ReplayBuffer"]


class ReplayBuffer:
    """A ring buffer of named fields, e.g. ``ReplayBuffer(10_000, obs=(8,), action=(), reward=())``.

    ``sample`` draws uniformly with the buffer's own ``np.random.Generator`` and returns float32, int64
    and bool torch tensors (a bool field stays bool).
    """

    def __init__(self, capacity: int, rng: np.random.Generator, dtypes: dict[str, Any] | None = None,
                 **shapes: tuple[int, ...]):
        if capacity <= 0:
            raise ValueError(f"replay capacity must be positive, got {capacity}")
        self.capacity = int(capacity)
        self.rng = rng
        dtypes = dtypes or {}
        self.data = {k: np.zeros((self.capacity, *shape), dtype=dtypes.get(k, np.float32))
                     for k, shape in shapes.items()}
        self.pos = 0
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(self, **values: Any) -> None:
        missing = set(self.data) - set(values)
        if missing:
            raise KeyError(f"replay add() is missing fields {sorted(missing)}")
        for k, arr in self.data.items():
            arr[self.pos] = values[k]
        self.pos = (self.pos + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch_size: int) -> dict[str, torch.Tensor]:
        idx = self.rng.integers(0, self.size, size=batch_size)
        out = {}
        for k, arr in self.data.items():
            t = torch.from_numpy(arr[idx])
            out[k] = t.long() if np.issubdtype(arr.dtype, np.integer) else t if arr.dtype == bool else t.float()
        return out

    def state_dict(self) -> dict[str, Any]:
        """The rows written so far (all of them once the ring is full), where it writes next, how many
        it holds and its capacity: a checkpoint early in a run does not carry the empty rest. (At least
        one row: an empty array pickles through ``bytes()``, which the safe loader refuses.)"""
        rows = max(self.size, 1)
        return {"data": {k: v[:rows].copy() for k, v in self.data.items()},
                "pos": self.pos, "size": self.size, "capacity": self.capacity}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Load :meth:`state_dict`'s state (or a full-capacity one, as earlier checkpoints hold)."""
        capacity = int(state.get("capacity", self.capacity))
        size = int(state["size"])
        for k, v in state["data"].items():
            if (k not in self.data or capacity != self.capacity or self.data[k].shape[1:] != v.shape[1:]
                    or not size <= len(v) <= self.capacity):
                raise ValueError(f"replay field {k!r} does not match this buffer's layout")
            self.data[k][: len(v)] = v
            self.data[k][len(v):] = 0
        self.pos, self.size = int(state["pos"]), size
