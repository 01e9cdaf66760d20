"""Where every random stream of a run comes from: one run seed, split by ``np.random.SeedSequence``.

A component draws from ``SeedSequence([seed, STREAM])`` with its own stream id below, so components
never share a stream and adding one does not shift the others. The ids are part of what a seed means:
changing one changes every run that uses it, so they are fixed here once and imported everywhere.

Training episode ``k`` is reset with :func:`episode_seed` ``(seed, k)``, i.e. ``SeedSequence([seed, k])``,
the same construction as the streams (the two families share the entropy ``[seed, k]`` for small ``k``:
an env reset and, say, the network initialisation then start from the same 32-bit word; harmless, as
they feed unrelated generators, and kept so that seeded runs reproduce).
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["NET_INIT_STREAM", "HIGH_LEVEL_STREAM", "LOW_LEVEL_STREAM", "CRITIC_STREAM", "EVAL_LOW_LEVEL_STREAM",
           "LOOP_STREAM",
           "SB3_STREAM", "HIRO_STREAM", "HIGL_STREAM", "EVAL_SEED_OFFSET", "SB3_EVAL_EPISODE", "seed_sequence",
           "stream_seed", "stream_rng", "stream_generator", "episode_seed"]

#: hierarchical agents: the torch generator of every network initialisation (and GoalTD3's noise)
NET_INIT_STREAM = 1
#: hierarchical agents: the high level's ε-greedy choices and replay sampling
HIGH_LEVEL_STREAM = 2
#: hierarchical agents: the low level's exploration, replay sampling and relabelling
LOW_LEVEL_STREAM = 3
#: HUBS-GO: the sub-goal critic (its seed, ``experiments.run``)
CRITIC_STREAM = 4
#: hierarchical agents in greedy evaluation: the low level's random steps (its cycle rule), drawn from
#: ``SeedSequence([episode seed, EVAL_LOW_LEVEL_STREAM])`` so that an evaluation episode depends on the
#: checkpoint and its seed only, and leaves the training streams as they were
EVAL_LOW_LEVEL_STREAM = 5
#: the HRL loop's own coin: choose from Ĝt or from G0
LOOP_STREAM = 7
#: flat baselines: the seed handed to Stable-Baselines3
SB3_STREAM = 11
#: HIRO: its torch generator, and (spawned from the same sequence) its numpy generator
HIRO_STREAM = 21
#: HIGL: its landmarks (the pool the coverage landmarks are drawn from); its networks are HIRO's
HIGL_STREAM = 22

#: ``evaluate``: episode ``i`` is reset with ``episode_seed(seed + EVAL_SEED_OFFSET, i)``, so evaluation
#: episodes do not replay training episodes
EVAL_SEED_OFFSET = 1_000_003
#: flat baselines: the episode index whose seed an evaluation episode uses when given none
SB3_EVAL_EPISODE = 10**6


def seed_sequence(seed: int, stream: int) -> np.random.SeedSequence:
    """``SeedSequence([seed, stream])``."""
    return np.random.SeedSequence([seed, stream])


def stream_seed(seed: int, stream: int) -> int:
    """The first 32-bit word of ``SeedSequence([seed, stream])``, as an int (for APIs that take a seed)."""
    return int(seed_sequence(seed, stream).generate_state(1)[0])


def stream_rng(seed: int, stream: int) -> np.random.Generator:
    """A numpy generator on ``SeedSequence([seed, stream])``."""
    return np.random.default_rng(seed_sequence(seed, stream))


def stream_generator(seed: int, stream: int) -> torch.Generator:
    """A torch generator seeded with :func:`stream_seed`."""
    return torch.Generator().manual_seed(stream_seed(seed, stream))


def episode_seed(seed: int, episode: int) -> int:
    """The env seed of episode ``episode`` of a run seeded ``seed`` (so resumed runs replay exactly)."""
    return stream_seed(seed, episode)
