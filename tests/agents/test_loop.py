"""The one HRL loop: Sec. 3.4's choice between Ĝt and G0, Algorithm 1's update order, seeding."""

import numpy as np
import pytest
import torch

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
        self.rows = 0          # transitions seen over all updates
        self.weights = []
        self.settled = []

    def allowed(self, achieved=None):
        return self.mask

    def update(self, batch):
        self.updates += 1
        self.rows += batch.q_next.shape[0]
        self.weights.append(batch.weight)
        self.settled.append(batch.settled)
        return {"critic/loss": 1.0}

    def end_episode(self, visited, success):
        self.ended = getattr(self, "ended", []) + [(np.asarray(visited).copy(), bool(success))]

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
    loop = _loop(extra=["loop.filter_refresh=option"])     # Ĝt read at every choice
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
    loop = _loop(steps=400, extra=["loop.critic_every=1"])     # Algorithm 1 to the letter
    filt = FixedSetFilter([True] * 5)
    loop.filter = filt
    while loop.env_steps < 400:
        loop.run_episode(train=True)
    assert loop.high.updates > 0 and filt.updates == loop.high.updates
    assert set(filt.weights) == {1.0}
    # critic_every = 4 pools four minibatches per critic update, across episode boundaries
    loop4 = _loop(steps=400, extra=["loop.critic_every=4"])
    filt4 = FixedSetFilter([True] * 5)
    loop4.filter = filt4
    while loop4.env_steps < 400:
        loop4.run_episode(train=True)
    assert loop4.high.updates > 8 and filt4.updates == loop4.high.updates // 4
    assert filt4.rows == 4 * filt4.updates * loop4.high.cfg.batch_size     # each minibatch seen once
    assert set(filt4.weights) == {0.25}
    # the minibatches still pending travel with the checkpoint
    pending = loop4.high.updates % 4
    other = _loop(steps=400, extra=["loop.critic_every=4"])
    other.filter = FixedSetFilter([True] * 5)
    other.load_state_dict(loop4.state_dict())
    assert len(other._pending) == len(loop4._pending) == pending
    for a, b in zip(other._pending, loop4._pending):
        assert torch.equal(a.q_next, b.q_next) and torch.equal(a.available, b.available)


def test_filter_refresh_per_episode_holds_ghat_for_the_whole_episode():
    class Flipping(FixedSetFilter):
        def allowed(self, achieved=None):        # a new Ĝt after every read
            self.reads = getattr(self, "reads", 0) + 1
            return np.roll(self.mask, self.reads)

    for refresh, max_sets in (("episode", 1), ("option", None)):
        loop = _loop(extra=[f"loop.filter_refresh={refresh}", "loop.filter_given_achieved=false"])
        loop.filter = Flipping([True, False, False, False, False])
        loop._filter = lambda progress: 1.0
        loop.high.select = lambda obs, allowed, eps: int(np.flatnonzero(allowed)[0])
        stats = loop.run_episode(train=True)
        assert stats.options > 2
        if max_sets:
            assert len(set(stats.chosen)) == max_sets
        else:
            assert len(set(stats.chosen)) > 1
    with pytest.raises(ValueError, match="filter_refresh"):
        _loop(extra=["loop.filter_refresh=sometimes"])


def test_ghat_is_read_given_the_achieved_subgoals_when_they_change():
    class Recording(FixedSetFilter):
        """Ĝt = the fixed mask plus whatever was achieved (so the answer shows what it was given)."""

        def allowed(self, achieved=None):
            self.given = getattr(self, "given", []) + [None if achieved is None else np.array(achieved)]
            return self.mask if achieved is None else self.mask | np.asarray(achieved, dtype=bool)

    none = np.zeros(5, bool)
    holds_blue_key = np.array([False, False, True, False, False])
    for given in (True, False):
        loop = _loop(extra=["loop.filter_refresh=episode", f"loop.filter_given_achieved={str(given).lower()}"])
        loop.filter = filt = Recording([True, True, False, False, True])
        loop._read_filter(none)                               # what run_episode does first
        loop._allowed(none, filter_eps=1.0)
        assert len(filt.given) == 1                           # same achieved set: Ĝt is held
        loop._allowed(holds_blue_key, filter_eps=1.0)
        if given:
            assert len(filt.given) == 2 and filt.given[-1].tolist() == holds_blue_key.tolist()
        else:
            assert len(filt.given) == 1 and filt.given[0] is None
        # the TD targets: one Ĝt per row of the minibatch, given what each s' has achieved
        rows = torch.tensor([none.tolist(), holds_blue_key.tolist()])
        mask = loop._target_mask(rows)
        if given:
            assert mask.tolist() == [[True, True, False, False, True], [True, True, True, False, True]]
        else:
            assert mask.tolist() == [True, True, False, False, True]
        loop.filter = NoFilterLike = FixedSetFilter(None)      # h-DQN: no Ĝt, targets over G0
        NoFilterLike.allowed = lambda achieved=None: None
        assert loop._target_mask(rows) is None


def test_low_level_steps_at_random_where_it_already_acted_greedily_under_the_same_goal():
    """A greedy low level stuck on a no-op (pickup facing nothing) is pushed out of it while training
    and in greedy evaluation; a state first reached by a random step is not marked."""
    for breaks in (True, False):
        loop = _loop(extra=[f"loop.low_break_cycles={str(breaks).lower()}"])
        loop._low_explore = lambda progress: 0.0
        loop.high.select = lambda obs, allowed, eps: 4                     # always the goal
        greedy, calls = set(), []
        pickup = loop.env.unwrapped.action_names.index("pickup")

        def act(obs, goal, eps, env, greedy=greedy, calls=calls, low=loop.low):
            key = (goal, np.asarray(obs).tobytes())
            calls.append((key in greedy, eps))
            low.explored = eps >= 1.0
            if low.explored:
                return int(low.rng.integers(low.n_actions))
            greedy.add(key)
            return pickup

        loop.low.act = act
        stats = loop.run_episode(train=True)
        repeats = sum(r for r, _ in calls)
        assert repeats > 0
        if breaks:
            assert all((eps == 1.0) == repeat for repeat, eps in calls)
            assert stats.scalars["low/revisits"] == repeats
            assert sum(eps == 0.0 for _, eps in calls) == len(greedy)     # each state acted on greedily once
        else:
            assert {eps for _, eps in calls} == {0.0} and "low/revisits" not in stats.scalars
        for evaluation_breaks in (True, False):      # greedy evaluation: by the same rule, unless turned off
            loop.cfg.eval_break_cycles = evaluation_breaks
            calls.clear()
            greedy.clear()
            before = (loop.env_steps, loop.episodes, loop.low.rng.bit_generator.state)
            stats = loop.run_episode(train=False)
            # the random steps came from the episode's own stream: the training streams are untouched
            assert (loop.env_steps, loop.episodes, loop.low.rng.bit_generator.state) == before
            assert "low/revisits" not in stats.scalars
            assert loop.eval_breaks_cycles == (breaks and evaluation_breaks)
            if breaks and evaluation_breaks:
                assert sum(r for r, _ in calls) > 0
                assert all((eps == 1.0) == repeat for repeat, eps in calls)
            else:
                assert {eps for _, eps in calls} == {0.0}


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


def test_the_agent_settles_once_its_recent_success_reaches_settle_at_and_stays_settled():
    """The agent settles at the end of the episode that brings the success rate over the last
    outcome_window episodes to settle_at; the latch survives failures and a checkpoint. Training never
    reads the successes as settled: every critic batch, before and after, is an ordinary one."""
    loop = _loop(steps=2000, extra=["loop.outcome_window=4", "loop.settle_at=0.75", "loop.critic_every=1"])
    loop.filter = FixedSetFilter([True] * 5)
    while loop.high.updates == 0:                       # no success in a window of 4: never settled
        loop._recent.clear()
        loop.run_episode(train=True)
    assert loop.settled_step is None and set(loop.filter.settled) == {False}
    loop._recent.clear()
    loop._recent.extend([True, True, True])             # 3 of 4, whatever this episode does: settled
    loop.run_episode(train=True)
    assert loop.settled_step == loop.env_steps
    before = len(loop.filter.settled)
    loop._recent.extend([False] * 4)                    # failures afterwards do not unsettle it
    loop.run_episode(train=True)
    assert loop.settled_step is not None and len(loop.filter.settled) > before
    assert set(loop.filter.settled) == {False}
    other = _loop(steps=2000, extra=["loop.outcome_window=4", "loop.settle_at=0.75"])
    other.filter = FixedSetFilter([True] * 5)
    other.load_state_dict(loop.state_dict())
    assert other.settled_step == loop.settled_step
    never = _loop(extra=["loop.outcome_window=4", "loop.settle_at=null"])
    never._recent.extend([True] * 4)
    never.run_episode(train=True)
    assert never.settled_step is None
    with pytest.raises(ValueError, match=r"^loop.settle_at takes a number in \(0, 1\], or null \(default 0.9\), got 1.5$"):
        _loop(extra=["loop.settle_at=1.5"])
    with pytest.raises(ValueError, match=r"^loop.settle_updates takes an integer >= 1 \(default 300\), got 0$"):
        _loop(extra=["loop.settle_updates=0"])


def test_g_star_is_read_from_the_critic_refitted_at_the_settled_power_once_the_agent_settles():
    """Before the agent settles G* comes from the filter's critic; once it has settled, from a copy
    refitted for settle_updates updates on the window of recent successes at the settled power, the
    same copy until the critic or the step moves on; the filter's critic is untouched."""
    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.infer.config import InferenceConfig
    from hubsgo_ppl.infer.critic import SubgoalCritic

    register()
    names = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]
    graph = SubgoalGraph(names, [("yellow_key", "yellow_door", 1), ("blue_key", "blue_door", 1),
                                 ("yellow_door", "goal", 1), ("blue_door", "goal", 1)])
    critic = SubgoalCritic(graph, "ising", {"strength": 3.0, "field": -2.0}, "outcome", {},
                           config=InferenceConfig(init="prior"), seed=0)
    cfg = apply_overrides(preset("minigrid"), SMALL + ["loop.settle_updates=50"])
    loop = build_agent("hubsgo", make("keydoor", max_steps=60), cfg, seed=5, critic=critic)
    assert loop.g_star_critic() is critic
    route = np.array([1, 1, 0, 0, 1], dtype=bool)       # a key, its door and the goal
    for _ in range(10):
        loop.filter.end_episode(route, True)
    loop.settled_step = loop.env_steps
    before = {k: v.clone() for k, v in critic.state_dict().items() if isinstance(v, torch.Tensor)}
    read = loop.g_star_critic()
    assert read is not critic and loop.g_star_critic() is read
    want = critic.settled(loop.filter.outcomes(), 50)
    torch.testing.assert_close(read.state_dict()["theta"], want.state_dict()["theta"])
    assert not torch.equal(read.state_dict()["theta"], critic.state_dict()["theta"])
    after = critic.state_dict()
    assert all(torch.equal(v, after[k]) for k, v in before.items())
    loop.env_steps += 1                                 # the run moved on: read afresh
    assert loop.g_star_critic() is not read


def test_marginal_goal_weights_follow_the_critic_after_each_update():
    """low_goal_weight=marginal: after each critic update from evidence the low level weighs sub-goal g by its
    marginal, floored at 1 - filter_end; an update without evidence changes nothing; h-DQN weighs all alike."""
    from hubsgo_ppl.agents.filters import CriticFilter
    from hubsgo_ppl.graph import SubgoalGraph
    from hubsgo_ppl.infer.critic import SubgoalCritic

    class KnownMarginals(CriticFilter):
        """A critic filter whose marginals are set by the test; its updates learn from evidence or not."""

        marginal = [0.9, 0.1, 0.5, 0.3, 0.95]
        evidence = True

        def update(self, batch):
            return {"critic/loss": 1.0} if self.evidence else {}

        def marginals(self):
            return np.array(self.marginal)

    register()
    names = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]
    critic = SubgoalCritic(SubgoalGraph(names, [("yellow_key", "yellow_door", 1)]), seed=0)
    cfg = apply_overrides(preset("minigrid"), SMALL + ["loop.low_goal_weight=marginal", "loop.critic_every=1",
                                                       "loop.filter_end=0.6"])
    cfg["steps"] = 600
    loop = build_agent("hubsgo", make("keydoor", max_steps=60), cfg, seed=5, critic=critic)
    loop.filter = KnownMarginals(critic)
    loop._weighs_low = True
    assert loop.low.goal_weight is None                     # all alike before the critic's first update
    while loop.high.updates == 0:
        loop.run_episode(train=True)
    assert loop.low.goal_weight.tolist() == pytest.approx([0.9, 0.4, 0.5, 0.4, 0.95])     # floor 1 - 0.6
    KnownMarginals.marginal, KnownMarginals.evidence = [0.2, 0.2, 0.2, 0.2, 0.2], False
    updates = loop.high.updates
    while loop.high.updates == updates:
        loop.run_episode(train=True)
    assert loop.low.goal_weight.tolist() == pytest.approx([0.9, 0.4, 0.5, 0.4, 0.95])     # no evidence: kept
    KnownMarginals.evidence = True
    updates = loop.high.updates
    while loop.high.updates == updates:
        loop.run_episode(train=True)
    assert loop.low.goal_weight.tolist() == pytest.approx([0.4] * 5)
    other = build_agent("hubsgo", make("keydoor", max_steps=60), cfg, seed=5,
                        critic=SubgoalCritic(SubgoalGraph(names, [("yellow_key", "yellow_door", 1)]), seed=0))
    other.load_state_dict(loop.state_dict())
    assert torch.equal(other.low.goal_weight, loop.low.goal_weight)
    hdqn = _loop(extra=["loop.low_goal_weight=marginal"])                     # h-DQN: no critic to read
    while hdqn.env_steps < 200:
        hdqn.run_episode(train=True)
    assert hdqn.low.steps > 32 and hdqn.low.goal_weight is None               # trained, every sub-goal alike
    with pytest.raises(ValueError, match="^loop.low_goal_weight takes one of 'uniform', 'marginal' "):
        _loop(extra=["loop.low_goal_weight=ranked"])


def test_low_level_shaping_uses_the_env_potential_and_refuses_to_run_without_one():
    import torch

    from hubsgo_ppl.agents.low_level import GoalDQN, GoalDQNConfig

    def low(shaping, potential):
        cfg = GoalDQNConfig(hidden=(8,), batch_size=4, learning_starts=4, train_every=1, shaping=shaping)
        return GoalDQN(6, 2, 3, cfg, torch.Generator().manual_seed(0), np.random.default_rng(0), potential=potential)

    with pytest.raises(ValueError, match="subgoal_potential"):
        low(1.0, None)
    phi = lambda obs: torch.stack([-obs[..., 0], -obs[..., 1]], -1)      # noqa: E731
    plain, shaped = low(0.0, phi), low(1.0, phi)
    assert plain.potential is None and shaped.potential is phi
    for agent in (plain, shaped):
        for t in range(4):
            o = np.full(6, t / 4, np.float32)
            agent.observe(o, t % 3, o + 0.25, np.zeros(2, bool), np.zeros(2, bool), False)
    assert plain.q[0].weight.ne(shaped.q[0].weight).any()      # the shaped reward changed the update
    # the env side: symbolic KeyDoor observations give one potential per sub-goal
    loop = _loop(extra=["low.shaping=1.0"])
    assert loop.low.potential is not None
    obs, _ = loop.env.reset(seed=0)
    assert loop.low.potential(torch.as_tensor(obs)[None]).shape == (1, 5)


def test_the_filter_hears_each_training_episode_with_every_subgoal_achieved_on_the_way():
    loop = _loop(steps=3000)
    names = loop.names
    f = FixedSetFilter(np.ones(len(names), dtype=bool))
    loop.filter = f
    seen = []
    for _ in range(6):
        before = loop.env_steps
        stats = loop.run_episode(train=True)
        seen.append((stats, before))
    loop.run_episode(train=False)                           # evaluation episodes are not reported
    assert len(f.ended) == 6
    for (visited, success), (stats, _) in zip(f.ended, seen):
        assert success == stats.success
        # every option that ended on its sub-goal achieved it, so it was visited in this episode
        assert visited.dtype == bool and visited.shape == (len(names),)
        if success:
            assert visited[names.index("goal")]


def test_the_loop_logs_every_option_with_its_start_and_outcome():
    loop = _loop()
    for _ in range(3):
        stats = loop.run_episode()
        assert len(stats.option_log) == stats.options and [o["goal"] for o in stats.option_log] == stats.chosen
        assert sum(o["steps"] for o in stats.option_log) == stats.length
        assert all(0 < o["steps"] <= 6 for o in stats.option_log)
        assert not any(o["goal"] in o["from"] for o in stats.option_log)     # achieved sub-goals are not offered
        assert "option_log" not in stats.row()


def test_a_success_counts_a_lasting_subgoal_only_where_it_holds_at_the_end():
    """An env's ``subgoal_lasting`` marks states a success keeps (an arm task's placements): the filter
    hears them as they are when the episode succeeds, every other sub-goal as achieved at any step.
    FourRoom's doorways, marked lasting here, are crossed on the way and left by the end."""
    from hubsgo_ppl.experiments.resolve import resolve_hyper

    register()
    hyper = resolve_hyper("minigrid", "fourroom", "hdqn", [], steps=3000, low_level="scripted")

    def heard(lasting):
        env = make("fourroom")
        if lasting is not None:
            env.unwrapped.subgoal_lasting = lambda: lasting
        loop = build_agent("hdqn", env, hyper, seed=0)
        loop.filter = f = FixedSetFilter(np.ones(len(loop.names), dtype=bool))
        ends = []
        while len(ends) < 8:
            loop.run_episode(train=True)
            ends.append(env.unwrapped.subgoal_achieved().copy())    # the state the episode ended in
        return loop.names, [(v, s, e) for (v, s), e in zip(f.ended, ends) if s]

    names, plain = heard(None)
    doors = np.array([n != "goal" for n in names])
    assert plain and all(v[~doors].all() and v[doors].any() for v, _, _ in plain)   # crossed on the way
    _, marked = heard(doors)
    assert len(marked) == len(plain)            # the same seed: the same episodes
    for v, _, end in marked:
        assert not end[doors].any()
        assert not v[doors].any() and v[names.index("goal")]
