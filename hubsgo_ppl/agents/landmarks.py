"""HIGL's landmarks (Kim, Seo, Shin, "Landmark-Guided Subgoal Generation in Hierarchical Reinforcement
Learning", NeurIPS 2021): where they come from, the graph over them and the landmark the high level is
pulled towards. Plain numpy/torch functions, each checked against hand-computed cases in
``tests/agents/test_landmarks.py``; :mod:`.higl` puts them together.

- **Coverage:** :func:`farthest_point_sampling` over a pool of visited states' goal parts.
- **Novelty:** :class:`NoveltyCounts`, visit counts over goal-space cells (novelty ``1/sqrt(n)``); the
  novelty landmarks are the first-seen states of the least-visited cells. HIGL scores novelty with
  random network distillation; on grids of a few hundred cells exact counts measure the same thing
  (how rarely a place was visited) without a second network to train.
- **Graph:** :func:`shortest_paths` (Floyd-Warshall) over edge lengths that are the low level's
  value-estimated distances, edges longer than a cutoff removed.
- **Selection:** :func:`select_landmark`, the landmark ``l`` minimising ``d(s, l) + D(l, target)`` (the
  first landmark on the shortest path from ``s`` to the target) or the target itself when it is as
  close directly.
- **Loss:** :func:`landmark_loss`, ``||(ag + g - l̃) / scale||`` with the pseudo-landmark ``l̃`` at most
  ``δ`` from the achieved goal ``ag`` towards the selected landmark (:func:`pseudo_landmark`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

__all__ = ["farthest_point_sampling", "NoveltyCounts", "shortest_paths", "select_landmark", "pseudo_landmark",
           "landmark_loss"]


def farthest_point_sampling(points: np.ndarray, n: int) -> np.ndarray:
    """Indices of up to ``n`` points, each the farthest (Euclidean) from those chosen before it.

    The first is ``points[0]`` (pass a shuffled pool for a random start); ties go to the lowest index.
    Stops early once every point coincides with a chosen one, so the indices are distinct points.
    """
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0 or n <= 0:
        return np.zeros(0, dtype=np.int64)
    chosen = [0]
    nearest = np.linalg.norm(points - points[0], axis=-1)
    while len(chosen) < n:
        i = int(nearest.argmax())
        if nearest[i] <= 0.0:
            break
        chosen.append(i)
        nearest = np.minimum(nearest, np.linalg.norm(points - points[i], axis=-1))
    return np.asarray(chosen, dtype=np.int64)


class NoveltyCounts:
    """Visit counts over goal-space cells of side ``cell``; each cell keeps the first state seen in it.

    ``novelty(ag) = 1 / sqrt(n(cell(ag)))`` (1 for a cell never visited); :meth:`most_novel` returns the
    stored states of the ``k`` least-visited cells, ties in the order the cells were first visited.
    """

    def __init__(self, cell: float, obs_dim: int, goal_dim: int):
        self.cell = float(cell)
        self.obs_dim, self.goal_dim = obs_dim, goal_dim
        self.index: dict[tuple[int, ...], int] = {}
        self.counts: list[int] = []
        self.obs: list[np.ndarray] = []
        self.ag: list[np.ndarray] = []

    def key(self, ag: np.ndarray) -> tuple[int, ...]:
        return tuple(int(v) for v in np.floor(np.asarray(ag, dtype=np.float64) / self.cell + 0.5))

    def visit(self, obs: np.ndarray, ag: np.ndarray) -> None:
        k = self.key(ag)
        j = self.index.get(k)
        if j is None:
            self.index[k] = len(self.counts)
            self.counts.append(1)
            self.obs.append(np.asarray(obs, dtype=np.float32).copy())
            self.ag.append(np.asarray(ag, dtype=np.float32).copy())
        else:
            self.counts[j] += 1

    def count(self, ag: np.ndarray) -> int:
        j = self.index.get(self.key(ag))
        return 0 if j is None else self.counts[j]

    def novelty(self, ag: np.ndarray) -> float:
        return 1.0 / float(np.sqrt(max(self.count(ag), 1)))

    def most_novel(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """``(obs (m, D), ag (m, k))`` of the ``m = min(k, cells)`` least-visited cells."""
        order = np.argsort(np.asarray(self.counts, dtype=np.int64), kind="stable")[:k]
        if len(order) == 0:
            return np.zeros((0, self.obs_dim), np.float32), np.zeros((0, self.goal_dim), np.float32)
        return np.stack([self.obs[j] for j in order]), np.stack([self.ag[j] for j in order])

    def __len__(self) -> int:
        return len(self.counts)

    def state_dict(self) -> dict[str, Any]:
        n = len(self.counts)
        return {"counts": np.asarray(self.counts, dtype=np.int64),
                "keys": np.asarray(list(self.index), dtype=np.int64).reshape(n, self.goal_dim),
                "obs": np.stack(self.obs) if n else np.zeros((0, self.obs_dim), np.float32),
                "ag": np.stack(self.ag) if n else np.zeros((0, self.goal_dim), np.float32)}

    def load_state_dict(self, s: dict[str, Any]) -> None:
        keys = np.asarray(s["keys"], dtype=np.int64)
        self.index = {tuple(int(v) for v in k): j for j, k in enumerate(keys)}
        self.counts = [int(c) for c in s["counts"]]
        self.obs = [np.asarray(o, dtype=np.float32) for o in s["obs"]]
        self.ag = [np.asarray(a, dtype=np.float32) for a in s["ag"]]


def shortest_paths(dist: np.ndarray, cutoff: float) -> np.ndarray:
    """All-pairs shortest path lengths (Floyd-Warshall) over the directed edges ``dist[i, j]``.

    Edges longer than ``cutoff`` (and infinite or NaN ones) are removed; ``D[i, i] = 0``; ``inf`` where
    no path is left.
    """
    d = np.array(dist, dtype=np.float64)
    d[~np.isfinite(d) | (d > cutoff)] = np.inf
    np.fill_diagonal(d, 0.0)
    for k in range(len(d)):
        d = np.minimum(d, d[:, k:k + 1] + d[k:k + 1, :])
    return d


def select_landmark(d_cur: np.ndarray, d_to_target: np.ndarray, cutoff: float) -> np.ndarray:
    """For each state, the node to head for: the landmark ``l`` minimising ``d(s, l) + D(l, target)``,
    or the target (index ``L``) when reaching it directly is at least as short or nothing is reachable.

    Args:
        d_cur: ``(B, L + 1)`` distances from each state to the ``L`` landmarks and the target (last);
            edges longer than ``cutoff`` are removed, as in the graph.
        d_to_target: ``(L,)`` shortest path lengths from each landmark to the target.
    Returns:
        ``(B,)`` node indices in ``[0, L]``.
    """
    d = np.array(d_cur, dtype=np.float64)
    d[~np.isfinite(d) | (d > cutoff)] = np.inf
    through = d[:, :-1] + np.asarray(d_to_target, dtype=np.float64)[None, :]
    total = np.concatenate([through, d[:, -1:]], axis=1)
    best = np.argmin(total, axis=1)
    best[~np.isfinite(total.min(axis=1))] = d.shape[1] - 1
    # the direct edge wins ties: prefer the target over a landmark as short
    direct = d[:, -1] <= total[np.arange(len(d)), best]
    best[direct] = d.shape[1] - 1
    return best


def pseudo_landmark(ag: torch.Tensor, landmark: torch.Tensor, step: torch.Tensor | float) -> torch.Tensor:
    """The point at most ``step`` from ``ag`` towards ``landmark`` (the landmark itself when closer)."""
    diff = landmark - ag
    norm = diff.norm(dim=-1, keepdim=True)
    factor = torch.where(norm > step, step / norm.clamp_min(1e-12), torch.ones_like(norm))
    return ag + diff * factor


def landmark_loss(goal: torch.Tensor, ag: torch.Tensor, target: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """``mean_b ||(ag_b + goal_b - target_b) / scale||``: pulls the proposed goal (an offset from ``ag``)
    towards the pseudo-landmark ``target``; the gradient in ``goal`` points from the target to the goal's
    absolute position, so a descent step moves the goal towards the target."""
    return ((ag + goal - target) / scale).norm(dim=-1).mean()
