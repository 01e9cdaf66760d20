"""scripts/option_audit.py: the options that never reached their sub-goal from where they started."""

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
import option_audit  # noqa: E402  (a script module, not a package)


def _o(start, goal, steps, reached):
    return {"from": list(start), "goal": goal, "steps": steps, "reached": reached}


def test_the_audit_counts_options_that_never_reached_their_sub_goal_from_their_start():
    log = [_o([], "door", 10, False),           # the door before the key: never from {}, reached from {key}
           _o([], "key", 7, True),
           _o(["key"], "door", 4, True),
           _o(["key", "door"], "goal", 10, False),   # failed, but reached from the same set later: counted out
           _o(["key", "door"], "goal", 6, True),
           _o([], "door", 10, False),
           _o(["key"], "lever", 10, False)]     # never reached anywhere: nothing says it needs something
    out = option_audit.audit(log)
    assert out == {"options": 7, "steps": 57, "never_options": 2, "never_steps": 20,
                   "never_step_share": pytest.approx(20 / 57)}


def test_reach_by_subgoal_counts_tries_and_successes_per_sub_goal():
    log = [_o([], "door", 10, False), _o([], "key", 7, True), _o(["key"], "door", 4, True),
           _o(["key", "door"], "goal", 10, False), _o([], "door", 10, False)]
    assert option_audit.reach_by_subgoal(log) == {"door": [3, 1], "goal": [1, 0], "key": [1, 1]}
    assert list(option_audit.reach_by_subgoal(log)) == ["door", "goal", "key"]
