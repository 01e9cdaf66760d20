"""The one HRL loop: Sec. 3.4's choice between Ĝt and G0, Algorithm 1's update order, seeding."""

import numpy as np
import pytest

from hubsgo_ppl.agents.factory import build_agent
from hubsgo_ppl.agents.presets import apply_overrides, preset
from hubsgo_ppl.envs import make, register

SMALL = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=32", "low.batch_size=16",
         "low.hidden=[16]", "high.hidden=[16]", "env.max_steps=60", "loop.option_steps=6"]


class FixedSetFilter:
    """A filter whose Ĝt is fixed; counts the updates it is given."""

    name = "fixed"

    def __init__(self, mask):
        self.mask = np.asarray(mask, dtype=bool)
        self.updates = 0

    def allowed(self):
        return self.mask

    def update(self, batch):
        self.updates += 1
        return {"critic/loss": 1.0}

    def state_dict(self):
        return {"updates": self.updates}

    def load_state_dict(self, s):
        self.updates = s["updates"]


def _loop(agent="hdqn", steps=600, extra=()):
    register()
    cfg = apply_overrides(preset("minigrid"), SMALL + list(extra))
    cfg["steps"] = steps
    env = make("keydoor", max_steps=60)
    return build_agent(agent, env, cfg, seed=5)


def test_allowed_set_follows_filter_eps_and_never_offers_achieved_subgoals():
    loop = _loop()
    loop.filter = FixedSetFilter([True, True, False, False, True])
    achieved = np.array([True, False, False, False, False])
    only_ghat = loop._allowed(achieved, filter_eps=1.0)
    assert only_ghat.tolist() == [False, True, False, False, True]
    g0 = loop._allowed(achieved, filter_eps=0.0)
    assert g0.tolist() == [False, True, True, True, True]
    # Ĝt ∩ not-achieved empty: fall back to G0 rather than offering nothing
    loop.filter = FixedSetFilter([True, False, False, False, False])
    assert loop._allowed(achieved, filter_eps=1.0).tolist() == [False, True, True, True, True]
    # the coin is drawn with probability filter_eps
    loop.filter = FixedSetFilter([True, True, False, False, True])
    hits = sum(loop._allowed(achieved, 0.3).tolist() == only_ghat.tolist() for _ in range(2000))
    assert abs(hits / 2000 - 0.3) < 0.04


def test_filter_is_updated_once_per_high_level_update_or_every_k():
    loop = _loop(steps=400)
    filt = FixedSetFilter([True] * 5)
    loop.filter = filt
    while loop.env_steps < 400:
        loop.run_episode(train=True)
    assert loop.high.updates > 0 and filt.updates == loop.high.updates
    loop4 = _loop(steps=400, extra=["loop.critic_every=4"])
    filt4 = FixedSetFilter([True] * 5)
    loop4.filter = filt4
    while loop4.env_steps < 400:
        loop4.run_episode(train=True)
    assert filt4.updates == loop4.high.updates // 4


def test_options_end_on_achievement_and_chosen_subgoals_come_from_the_allowed_set():
    loop = _loop()
    loop.filter = FixedSetFilter([False, False, True, True, True])   # only the blue route and the goal
    loop._filter = lambda progress: 1.0                                # always choose from Ĝt
    stats = [loop.run_episode(train=True) for _ in range(5)]
    chosen = {g for s in stats for g in s.chosen}
    assert chosen <= {"blue_key", "blue_door", "goal"}
    assert all(s.options >= 1 and s.length <= 60 for s in stats)


def test_eval_episode_does_not_advance_training_counters():
    loop = _loop()
    loop.run_episode(train=True)
    before = (loop.env_steps, loop.episodes, loop.high.updates)
    loop.run_episode(train=False, seed=123)
    assert (loop.env_steps, loop.episodes, loop.high.updates) == before
