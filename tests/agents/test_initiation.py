"""Learned initiation sets: the sub-goals whose options rarely succeed from an achieved set."""

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


def test_a_sub_goal_is_blocked_where_its_rate_is_under_a_kth_of_its_best_rate():
    init = InitiationSets(NAMES, after=3)
    start, holding = _set(), _set("key")
    _tries(init, start, 1, 0, 5)                    # the door fails from the start, and nothing says it
    assert not init.blocked(start).any()            # can be reached anywhere: nothing is blocked
    _tries(init, holding, 1, 1, 0)                  # one success with the key: fewer than K tries there,
    assert not init.blocked(start).any()            # so no rate to compare with yet
    _tries(init, holding, 1, 2, 0)                  # 3 of 3 with the key
    assert init.best_rates().tolist() == [0.0, 1.0, 0.0, 0.0]
    assert init.blocked(start).tolist() == [False, True, False, False]
    assert not init.blocked(holding).any()          # where it is best it stays open
    assert not init.blocked(_set("other_key")).any()    # a set never tried blocks nothing
    _tries(init, _set("other_key"), 1, 0, 2)       # two failures with the other key: fewer than K
    assert not init.blocked(_set("other_key")).any()
    _tries(init, _set("other_key"), 1, 0, 1)
    assert init.blocked(_set("other_key"))[1]
    _tries(init, start, 1, 1, 0)                    # 1 in 6 from the start: 3 / 6 < 1, still blocked
    assert init.blocked(start)[1]
    _tries(init, start, 1, 2, 0)                    # 3 in 8: 9 / 8 >= 1, open again
    assert not init.blocked(start)[1]
    assert [c.tolist() for c in init.counts(start)] == [[0, 8, 0, 0], [0, 3, 0, 0]]


def test_an_option_that_succeeds_only_by_doing_another_sub_goal_on_the_way_is_blocked():
    init = InitiationSets(NAMES, after=10)
    _tries(init, _set("key"), 3, 6, 94)             # the goal from "holding the key": 6% (door opened in passing)
    _tries(init, _set("key", "door"), 3, 9, 1)      # through the open door: 90%
    assert init.blocked(_set("key")).tolist() == [False, False, False, True]
    _tries(init, _set("key"), 3, 4, 0)              # 10 in 104: 96% of the best, no longer under a tenth
    assert not init.blocked(_set("key")).any()
    low = InitiationSets(NAMES, after=10)           # a skill still being learned: its only rate is low
    _tries(low, _set(), 0, 2, 19)
    assert not low.blocked(_set()).any()


def test_the_counts_travel_by_name():
    init = InitiationSets(NAMES, after=2)
    _tries(init, _set(), 3, 0, 2)                   # the goal fails from the start ...
    _tries(init, _set("key", "other_key"), 3, 0, 2)
    _tries(init, _set("key", "door"), 3, 2, 0)      # ... and is reached through the door
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
