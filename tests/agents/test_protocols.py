"""The contracts as code: every trainer and low level satisfies its protocol, the loop calls members
(a low level that implements only ``act`` runs in it), and the shared episode skeleton."""

import numpy as np
import pytest
import torch

from hubsgo_ppl.agents.episode import EpisodeTally, reset_episode, sequential_mean
from hubsgo_ppl.agents.factory import build_agent
from hubsgo_ppl.agents.presets import apply_overrides, preset
from hubsgo_ppl.agents.protocols import HIROLowLevel, LowLevel, LowLevelBase, Trainer
from hubsgo_ppl.agents.seeding import (CRITIC_STREAM, EVAL_SEED_OFFSET, HIGH_LEVEL_STREAM, HIRO_STREAM, LOOP_STREAM,
                                       LOW_LEVEL_STREAM, NET_INIT_STREAM, SB3_EVAL_EPISODE, SB3_STREAM, episode_seed)
from hubsgo_ppl.envs import make, register

SMALL = ["high.learning_starts=8", "high.batch_size=8", "low.learning_starts=32", "low.batch_size=16",
         "low.hidden=[16]", "high.hidden=[16]", "loop.option_steps=6", "hiro.hidden=[16]", "hiro.batch_size=8",
         "dqn.learning_starts=32", "dqn.batch_size=8"]


def _agent(name, steps=300):
    register()
    cfg = apply_overrides(preset("minigrid"), SMALL)
    cfg["steps"] = steps
    return build_agent(name, make("keydoor", max_steps=60), cfg, seed=1)


@pytest.mark.parametrize("name", ["hdqn", "hiro", "ddqn"])
def test_every_trainer_satisfies_the_trainer_protocol(name):
    agent = _agent(name)
    assert isinstance(agent, Trainer)
    assert agent.cfg.total_steps == 300 and agent.episodes == 0 and agent.env_steps == 0


def test_low_levels_satisfy_their_protocols():
    from hubsgo_ppl.agents.hiro import GoalDQNLow, HIROConfig
    from hubsgo_ppl.agents.low_level import ScriptedLowLevel
    from hubsgo_ppl.agents.scripted_osc import ScriptedOSC

    loop = _agent("hdqn")
    assert isinstance(loop.low, LowLevel) and loop.low.learns and loop.low.rng is not None
    scripted = ScriptedLowLevel(ScriptedOSC())
    assert isinstance(scripted, LowLevel)
    assert not scripted.learns and scripted.explored and scripted.rng is None
    assert scripted.begin_option() is None and scripted.observe(None, None, None, None, None, False) is None
    assert scripted.state_dict() == {}
    low = GoalDQNLow(4, np.ones(2, np.float32), 3, HIROConfig(hidden=(8,)), torch.Generator().manual_seed(0))
    assert isinstance(low, HIROLowLevel)


def test_a_low_level_with_only_act_runs_in_the_loop():
    class Random(LowLevelBase):
        def __init__(self):
            self.calls, self.options = 0, 0

        def act(self, obs, goal, explore_eps, env):
            self.calls += 1
            return int(env.action_space.sample())

        def begin_option(self):
            self.options += 1

    loop = _agent("hdqn")
    loop.low = Random()
    loop.env.action_space.seed(0)
    stats = loop.run_episode(train=True)
    assert loop.low.calls == stats.length and loop.low.options == stats.options
    assert "low/td_loss" not in stats.scalars
    assert "low" not in loop.state_dict()        # learns = False: nothing of it is checkpointed


def test_episode_tally_and_reset():
    tally = EpisodeTally(3)
    tally.note({"is_success": False})
    for r, ok in ((0.0, False), (0.5, True), (0.0, False)):
        tally.step(r, {"is_success": ok})
    values = [0.1, 0.2, 0.3, 1e-17, 0.7, 0.1, 0.9, 0.3, 0.2, 5.0]
    tally.record({"a": values[0]})
    for v in values[1:]:
        tally.record({"a": v})
    tally.record(None)
    tally.put("b", 4.0)
    s = tally.stats(10, options=2, explore_eps=0.1, filter_eps=0.2, chosen=["x"])
    assert (s.episode, s.ret, s.length, s.success, s.env_steps, s.chosen) == (3, 0.5, 3, True, 10, ["x"])
    total = 0.0
    for v in values:
        total += v
    assert s.scalars == {"a": total / len(values), "b": 4.0} and sequential_mean(values) == total / len(values)
    assert EpisodeTally(0, mean=np.mean).means() == {}
    register()
    env = make("keydoor")
    a, _ = reset_episode(env, 7, 2)
    b, _ = env.reset(seed=episode_seed(7, 2))
    c, _ = reset_episode(env, 7, 2, seed=episode_seed(7, 2))
    assert np.array_equal(a, b) and np.array_equal(a, c)


def test_stream_ids_are_fixed():
    """The stream ids are part of what a seed means: changing one changes every seeded run."""
    assert (NET_INIT_STREAM, HIGH_LEVEL_STREAM, LOW_LEVEL_STREAM, CRITIC_STREAM, LOOP_STREAM, SB3_STREAM,
            HIRO_STREAM) == (1, 2, 3, 4, 7, 11, 21)
    assert (EVAL_SEED_OFFSET, SB3_EVAL_EPISODE) == (1_000_003, 10**6)
    assert episode_seed(0, 0) == int(np.random.SeedSequence([0, 0]).generate_state(1)[0])
