"""Learned initiation sets: the sub-goals whose options never succeed from an achieved set."""

import numpy as np
import pytest

from hubsgo_ppl.agents.initiation import InitiationSets

NAMES = ["key", "door", "other_key", "goal"]


def _set(*names):
    return np.array([n in names for n in NAMES])


def _tries(init, achieved, goal, hits, misses):
    for _ in range(hits):
        init.record(achieved, goal, True)
    for _ in range(misses):
        init.record(achieved, goal, False)


def test_a_sub_goal_is_blocked_after_k_failures_here_once_reached_from_a_set_holding_more():
    init = InitiationSets(NAMES, after=3)
    start, holding = _set(), _set("key")
    _tries(init, start, 1, 0, 5)                    # the door fails from the start, and nothing says it
    assert not init.blocked(start).any()            # can be reached anywhere: nothing is blocked
    _tries(init, holding, 1, 1, 0)                  # reached with the key
    assert init.blocked(start).tolist() == [False, True, False, False]
    assert not init.blocked(holding).any()          # where it was reached it stays open
    assert not init.blocked(_set("other_key")).any()    # a set never tried blocks nothing
    # with the other key the door fails K times, but it was reached only from {key}, which does not
    # hold the other key: what the door needs is not shown to be missing there, so it stays open
    _tries(init, _set("other_key"), 1, 0, 3)
    assert not init.blocked(_set("other_key")).any()
    # the goal, reached from {key, door}: blocked after K failures at the sets it holds more than
    _tries(init, _set("key", "door"), 3, 1, 0)
    _tries(init, holding, 3, 0, 3)
    _tries(init, _set("door"), 3, 0, 3)
    _tries(init, _set("other_key"), 3, 0, 3)
    assert init.blocked(holding).tolist() == [False, False, False, True]       # {key} < {key, door}
    assert init.blocked(_set("door")).tolist() == [False, False, False, True]  # {door} < {key, door}
    assert not init.blocked(_set("other_key")).any()                          # not a subset of it
    _tries(init, start, 1, 1, 0)                    # one success from the start opens it there
    assert not init.blocked(start).any()
    assert [c.tolist() for c in init.counts(start)] == [[0, 6, 0, 0], [0, 1, 0, 0]]


def test_an_option_that_succeeds_here_now_and_then_stays_open():
    init = InitiationSets(NAMES, after=10)
    _tries(init, _set("key", "door"), 3, 9, 1)      # the goal through the open door: 90%
    _tries(init, _set("key"), 3, 0, 10)             # from "holding the key": 10 failures, blocked
    assert init.blocked(_set("key")).tolist() == [False, False, False, True]
    _tries(init, _set("key"), 3, 1, 90)             # then once in 91 (the door opened in passing)
    assert not init.blocked(_set("key")).any()


def test_the_counts_travel_by_name():
    init = InitiationSets(NAMES, after=2)
    _tries(init, _set(), 3, 0, 2)                   # the goal fails from the start ...
    _tries(init, _set("key", "other_key"), 3, 0, 2)
    _tries(init, _set("key", "door"), 3, 1, 0)      # ... and is reached through the door
    state = init.state_dict()
    assert state["sets"][0] == {"achieved": [], "tries": {"goal": 2}, "hits": {}}
    # another order, "other_key" dropped, "lever" new
    other = InitiationSets(["goal", "lever", "door", "key"], after=2)
    other.load_state_dict(state)
    assert other.blocked(np.zeros(4, bool)).tolist() == [True, False, False, False]
    assert not other.blocked(np.array([False, False, True, True])).any()     # key and door: reached there
    # the set that named the dropped sub-goal is gone, not merged into {key}
    assert [c.tolist() for c in other.counts(np.array([False, False, False, True]))] == [[0] * 4, [0] * 4]
    again = InitiationSets(NAMES, after=2)
    again.load_state_dict(state)
    assert again.state_dict() == state


def test_k_must_be_positive():
    with pytest.raises(ValueError, match="loop.initiation_tries must be a positive integer"):
        InitiationSets(NAMES, after=0)
