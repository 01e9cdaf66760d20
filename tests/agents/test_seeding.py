"""Named random streams: every stream is SeedSequence([seed, stream]), and streams never coincide."""

import numpy as np
import torch

from hubsgo_ppl.agents import seeding
from hubsgo_ppl.agents.seeding import episode_seed, seed_sequence, stream_generator, stream_rng, stream_seed

STREAMS = [seeding.NET_INIT_STREAM, seeding.HIGH_LEVEL_STREAM, seeding.LOW_LEVEL_STREAM, seeding.CRITIC_STREAM,
           seeding.LOOP_STREAM, seeding.SB3_STREAM, seeding.HIRO_STREAM, seeding.HIGL_STREAM]


def test_each_helper_is_the_seed_sequence_of_seed_and_stream():
    seq = np.random.SeedSequence([42, seeding.CRITIC_STREAM])
    assert seed_sequence(42, seeding.CRITIC_STREAM).entropy == seq.entropy
    assert seed_sequence(42, seeding.CRITIC_STREAM).spawn_key == ()
    word = int(seq.generate_state(1)[0])
    assert stream_seed(42, seeding.CRITIC_STREAM) == word and isinstance(stream_seed(42, 4), int)
    assert stream_rng(42, seeding.CRITIC_STREAM).random(5).tolist() == np.random.default_rng(seq).random(5).tolist()
    ref = torch.Generator().manual_seed(word)
    assert torch.equal(torch.rand(4, generator=stream_generator(42, seeding.CRITIC_STREAM)),
                       torch.rand(4, generator=ref))
    assert episode_seed(42, 17) == int(np.random.SeedSequence([42, 17]).generate_state(1)[0])


def test_streams_and_seeds_do_not_collide():
    assert len(set(STREAMS)) == len(STREAMS)
    words = {stream_seed(seed, s) for seed in range(5) for s in STREAMS}
    assert len(words) == 5 * len(STREAMS)
    firsts = {tuple(stream_rng(3, s).integers(0, 2**31, 3)) for s in STREAMS}
    assert len(firsts) == len(STREAMS)
    assert len({episode_seed(3, k) for k in range(200)}) == 200
