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


def test_the_loop_logs_every_option_with_its_start_and_outcome():
    from hubsgo_ppl.agents.factory import build_agent
    from hubsgo_ppl.agents.presets import apply_overrides, preset
    from hubsgo_ppl.envs import make, register

    register()
    cfg = apply_overrides(preset("minigrid"), ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=32",
                                               "low.batch_size=16", "low.hidden=[16]", "high.hidden=[16]",
                                               "loop.option_steps=6"])
    cfg["steps"] = 600
    loop = build_agent("hdqn", make("keydoor", max_steps=60), cfg, seed=5)
    for _ in range(3):
        stats = loop.run_episode()
        assert len(stats.option_log) == stats.options and [o["goal"] for o in stats.option_log] == stats.chosen
        assert sum(o["steps"] for o in stats.option_log) == stats.length
        assert all(0 < o["steps"] <= 6 for o in stats.option_log)
        assert not any(o["goal"] in o["from"] for o in stats.option_log)     # achieved sub-goals are not offered
        assert "option_log" not in stats.row()
