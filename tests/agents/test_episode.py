"""The episode skeleton: the metrics row of an episode, its reset seed and options, success from reset."""

import numpy as np

from hubsgo_ppl.agents.episode import EpisodeStats, EpisodeTally, reset_episode
from hubsgo_ppl.agents.seeding import episode_seed


class FakeEnv:
    def __init__(self):
        self.calls = []

    def reset(self, **kwargs):
        self.calls.append(kwargs)
        return np.zeros(2), {"is_success": True}


def test_row_is_the_metrics_csv_row():
    stats = EpisodeStats(episode=4, env_steps=120, ret=0.75, length=30, success=True, options=3, explore_eps=0.2,
                         filter_eps=0.6, chosen=["key", "door"], scalars={"critic/loss": 1.5, "high/td_loss": 0.1})
    assert stats.row() == {"episode": 4, "env_steps": 120, "return": 0.75, "length": 30, "success": 1, "options": 3,
                           "explore_eps": 0.2, "filter_eps": 0.6, "critic/loss": 1.5, "high/td_loss": 0.1}
    assert EpisodeStats(0, 1, 0.0, 1, False, 1, 0.0, 0.0).row()["success"] == 0


def test_reset_uses_the_episode_seed_or_the_given_one_and_passes_options():
    env = FakeEnv()
    reset_episode(env, 7, 3)
    reset_episode(env, 7, 3, seed=11, options={"start": 2})
    assert env.calls == [{"seed": episode_seed(7, 3)}, {"seed": 11, "options": {"start": 2}}]


def test_success_on_reset_counts_only_when_noted():
    env = FakeEnv()
    _, info = reset_episode(env, 0, 0)
    counted, ignored = EpisodeTally(0), EpisodeTally(0)
    counted.note(info)
    for tally in (counted, ignored):
        tally.step(0.0, {"is_success": False})
    assert counted.success and not ignored.success
    assert counted.stats(1, 1, 0.0, 0.0).success is True


def test_tally_means_sum_left_to_right_unless_given_another_reducer():
    # the exact mean is 0.5; summed left to right 1e16 + 1 rounds back to 1e16 (the spacing there is 2),
    # so the running sum ends at 1 and the mean is 0.25
    values = [1e16, 1.0, -1e16, 1.0]
    seq, largest = EpisodeTally(0), EpisodeTally(0, mean=max)
    for tally in (seq, largest):
        for v in values:
            tally.record({"x": v, "y": 2.0})
        tally.record(None)                                  # no update ran: nothing recorded
        tally.put("once", 7.0)
    assert seq.means() == {"x": 0.25, "y": 2.0, "once": 7.0}
    assert largest.means() == {"x": 1e16, "y": 2.0, "once": 7.0}
    assert seq.stats(5, 2, 0.1, 0.2).scalars == {"x": 0.25, "y": 2.0, "once": 7.0}
