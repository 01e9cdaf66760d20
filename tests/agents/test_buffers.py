"""The replay ring buffer: overwrite order, sampling, dtypes, and exact resume through state_dict."""

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.buffers import ReplayBuffer


def _buffer(capacity=3, seed=0):
    return ReplayBuffer(capacity, np.random.default_rng(seed), dtypes={"action": np.int64, "flag": bool},
                        obs=(2,), action=(), flag=())


def test_ring_overwrites_the_oldest_and_samples_only_what_it_holds():
    buf = _buffer()
    for i in range(5):
        buf.add(obs=[i, -i], action=i, flag=i % 2 == 0)
    assert len(buf) == 3 and buf.pos == 2
    assert buf.data["action"].tolist() == [3, 4, 2]          # 0 and 1 overwritten by 3 and 4
    batch = buf.sample(200)
    assert set(batch["action"].tolist()) == {2, 3, 4}
    assert torch.equal(batch["obs"][:, 0], batch["action"].float())
    assert torch.equal(batch["obs"][:, 1], -batch["action"].float())
    assert torch.equal(batch["flag"], batch["action"] % 2 == 0)
    assert (batch["obs"].dtype, batch["action"].dtype, batch["flag"].dtype) == (torch.float32, torch.int64,
                                                                                 torch.bool)


def test_sampling_follows_the_buffers_own_generator():
    a, b = _buffer(8, seed=5), _buffer(8, seed=5)
    for buf in (a, b):
        for i in range(8):
            buf.add(obs=[i, i], action=i, flag=False)
    idx = np.random.default_rng(5).integers(0, 8, size=16)
    assert a.sample(16)["action"].tolist() == idx.tolist()
    torch.testing.assert_close(b.sample(16), _as_batch(b, idx))


def _as_batch(buf, idx):
    return {"obs": torch.from_numpy(buf.data["obs"][idx]).float(),
            "action": torch.from_numpy(buf.data["action"][idx]).long(),
            "flag": torch.from_numpy(buf.data["flag"][idx])}


def test_state_dict_round_trip_and_layout_check():
    buf = _buffer(4)
    for i in range(6):
        buf.add(obs=[i, 0], action=i, flag=True)
    state = buf.state_dict()
    buf.add(obs=[9, 9], action=9, flag=False)             # the copy must not see later writes
    fresh = _buffer(4)
    fresh.load_state_dict(state)
    assert (fresh.pos, len(fresh)) == (2, 4)
    assert fresh.data["action"].tolist() == [4, 5, 2, 3]
    other = ReplayBuffer(4, np.random.default_rng(0), obs=(3,), action=(), flag=())
    with pytest.raises(ValueError, match="replay field 'obs' does not match"):
        other.load_state_dict(state)


def test_bad_use_fails_clearly():
    with pytest.raises(ValueError, match="capacity must be positive"):
        ReplayBuffer(0, np.random.default_rng(0), obs=(1,))
    with pytest.raises(KeyError, match=r"missing fields \['flag'\]"):
        _buffer().add(obs=[0, 0], action=1)


def test_the_state_holds_only_the_rows_written_and_loads_full_capacity_states_too():
    buf = _buffer(capacity=10)
    assert len(buf.state_dict()["data"]["obs"]) == 1            # empty: one zero row (see state_dict)
    for i in range(4):
        buf.add(obs=[i, i], action=i, flag=True)
    state = buf.state_dict()
    assert {k: len(v) for k, v in state["data"].items()} == {"obs": 4, "action": 4, "flag": 4}
    assert (state["capacity"], state["size"], state["pos"]) == (10, 4, 4)
    old_style = {"data": {k: v.copy() for k, v in buf.data.items()}, "pos": 4, "size": 4}    # full capacity
    for s in (state, old_style):
        other = _buffer(capacity=10)
        other.add(obs=[9, 9], action=9, flag=False)             # rows past the loaded ones are cleared
        other.add(obs=[9, 9], action=9, flag=False)
        other.add(obs=[9, 9], action=9, flag=False)
        other.add(obs=[9, 9], action=9, flag=False)
        other.add(obs=[9, 9], action=9, flag=False)
        other.load_state_dict(s)
        for k in buf.data:
            assert np.array_equal(other.data[k], buf.data[k]), k
        assert (other.pos, other.size) == (4, 4)
    with pytest.raises(ValueError, match="does not match"):
        _buffer(capacity=12).load_state_dict(state)             # another capacity
    with pytest.raises(ValueError, match="does not match"):
        _buffer(capacity=10).load_state_dict({**state, "size": 5})    # fewer rows than it claims to hold
