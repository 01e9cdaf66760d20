"""The compiled critic step (``inference.jit``, CompiledTraceGraph_ELBO) against the eager one.

The compiled step must be the same estimator, not an approximation of it: from the same seed, an eager
critic and a compiled one take bit-identical steps (parameters, chains, Pyro's decaying-average
baseline, diagnostics), whatever the prior, likelihood, normaliser path, mask or pool weight. Its
gradient also matches exact enumeration (tests/infer/test_critic.py::test_gradient_matches_exact_enumeration
runs TDBatch updates, which are compiled from the second one on).
"""

import pyro
import pytest
import torch

from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.critic import CompiledTraceGraph_ELBO, InferenceConfig, SubgoalCritic, TDBatch

GRAPH = SubgoalGraph(
    ["door_top", "door_left", "door_right", "door_bottom", "goal"],
    [("door_top", "door_right", 1), ("door_left", "door_bottom", 1), ("door_top", "door_left", -1),
     ("door_right", "door_bottom", -1), ("door_right", "goal", 1), ("door_bottom", "goal", 1)],
)
BASELINE = "__baseline_avg_downstream_cost_w"


def batch(seed: int, b: int = 16, n: int = 5, masked: bool = True, weight: float = 1.0) -> TDBatch:
    g = torch.Generator().manual_seed(seed)
    q = torch.randn(b, n, generator=g)
    return TDBatch(q[:, 0] + 0.3, q, torch.rand(b, generator=g), torch.full((b,), 0.9),
                   available=(torch.rand(b, n, generator=g) > 0.2) if masked else None, weight=weight)


def pair(jit_config: dict, **critic_kwargs) -> tuple[SubgoalCritic, SubgoalCritic]:
    eager = SubgoalCritic(GRAPH, config=InferenceConfig(jit=False, **jit_config), seed=11, **critic_kwargs)
    compiled = SubgoalCritic(GRAPH, config=InferenceConfig(jit=True, **jit_config), seed=11, **critic_kwargs)
    return eager, compiled


def assert_same_state(a: SubgoalCritic, b: SubgoalCritic) -> None:
    sa, sb = a.state_dict(), b.state_dict()
    for key in ("theta", "coupling", "chains", "last_samples", "rng"):
        assert torch.equal(sa[key], sb[key]), key
    assert sa["baseline"].keys() == sb["baseline"].keys() == {BASELINE}
    assert torch.equal(sa["baseline"][BASELINE], sb["baseline"][BASELINE])
    assert sa["optimizer"]["state"][0]["exp_avg_sq"].equal(sb["optimizer"]["state"][0]["exp_avg_sq"])


@pytest.mark.parametrize(
    "prior, prior_params, likelihood, lik_params, config, masked, weight",
    [
        ("bernoulli", {}, "gaussian", {"scale": 0.5}, {}, True, 1.0),
        ("ising", {"strength": 3.0, "field": -2.0}, "gaussian", {"scale": 0.1}, {}, True, 0.25),  # FourRoom's
        ("beta_bernoulli", {"alpha": 2.0, "beta": 1.0}, "student_t", {"df": 3.0}, {}, False, 1.0),
        ("bernoulli", {"p": 0.3}, "laplace", {"scale": 0.7}, {"exact_max_n": 2}, True, 1.0),   # leave-one-out
        ("bernoulli", {}, "gaussian", {}, {"kernel": "block", "burn_in": 3, "num_samples": 8}, True, 1.0),
    ],
)
def test_compiled_steps_equal_eager_steps(prior, prior_params, likelihood, lik_params, config, masked, weight):
    eager, compiled = pair(config, prior=prior, prior_params=prior_params, likelihood=likelihood,
                           likelihood_params=lik_params)
    for step in range(12):
        b = batch(step, masked=masked, weight=weight)
        assert eager.update(b) == compiled.update(b), step     # every diagnostic, to the last bit
        assert torch.equal(eager.filtered_set(), compiled.filtered_set())
    assert_same_state(eager, compiled)
    assert len(compiled._compiled_elbo._compiled) == 1          # compiled once, reused 10 times
    assert not eager._compiled_elbo


def test_a_new_batch_shape_compiles_again_and_stays_exact():
    eager, compiled = pair({})
    compiled._compiled_elbo.compile_after = 1       # every shape compiled at once
    for step, (b, masked) in enumerate([(16, True), (16, True), (40, True), (16, False), (40, True), (16, True)]):
        tb = batch(step, b=b, masked=masked)
        assert eager.update(tb) == compiled.update(tb)
    assert_same_state(eager, compiled)
    assert len(compiled._compiled_elbo._compiled) == 3          # (16, mask), (40, mask), (16, no mask)


def test_a_shape_seen_a_few_times_runs_eagerly_and_one_seen_often_is_compiled_once():
    """A growing evidence window meets most of its shapes a few times: those run eagerly; a shape is
    compiled on its compile_after-th step. Either way the steps are the eager critic's, to the bit."""
    eager, compiled = pair({})
    after = compiled._compiled_elbo.compile_after
    shapes = [16] + [40] * 3 + [24] * (after + 2)
    for step, b in enumerate(shapes):
        assert eager.update(batch(step, b=b)) == compiled.update(batch(step, b=b)), step
    assert_same_state(eager, compiled)
    keys = compiled._compiled_elbo._compiled
    assert len(keys) == 1 and ((24, 5), torch.float32) in [s[:2] for s in next(iter(keys))[1]]


def test_callables_run_eagerly_and_mix_with_compiled_steps():
    """A residual callable cannot be traced; it takes the eager path, and the two paths share one state."""
    eager, compiled = pair({})
    fn = batch(99).residuals
    for step in range(6):
        b = fn if step % 2 else batch(step)
        assert eager.update(b) == compiled.update(b)
    assert_same_state(eager, compiled)


def test_resumed_compiled_critic_continues_identically():
    a = SubgoalCritic(GRAPH, seed=3)
    for step in range(5):
        a.update(batch(step))
    b = SubgoalCritic(GRAPH, seed=0)
    b.load_state_dict(a.state_dict())
    for step in range(5, 9):
        assert a.update(batch(step)) == b.update(batch(step))
    assert_same_state(a, b)


def test_compiling_does_not_move_the_baseline():
    """Compiling runs Pyro's loss twice; neither run may advance the decaying-average baseline."""
    eager, compiled = pair({"pyro_validation": "never"})   # no eager first update: the first call creates it
    for step in range(3):
        eager.update(batch(step))
        compiled.update(batch(step))
        assert torch.equal(eager.state_dict()["baseline"][BASELINE], compiled.state_dict()["baseline"][BASELINE])


def test_compiled_elbo_is_tied_to_its_model_and_guide():
    """The compiled ELBO runs the critic's one model and guide (the eager ELBO runs the same pair)."""
    critic = SubgoalCritic(GRAPH, seed=0)
    elbo = critic._compiled_elbo
    assert isinstance(elbo, CompiledTraceGraph_ELBO)
    assert elbo.model == critic._model and elbo.guide == critic._guide
    other = SubgoalCritic(GRAPH, seed=0)
    with pytest.raises(ValueError, match="another model and guide"):
        elbo.loss_and_grads(other._model, other._guide, other._draw(), *batch(0).tensors())
    assert BASELINE not in pyro.get_param_store()            # the critic's store stays private


def test_jit_setting_is_validated_and_read_from_specs():
    with pytest.raises(ValueError, match="InferenceConfig.jit"):
        InferenceConfig(jit="yes")
    from hubsgo_ppl.specs import load_model_spec

    spec = load_model_spec("fourroom-specific")
    assert spec.inference.jit is True
    spec.inference.jit = False
    assert SubgoalCritic.from_spec(spec)._compiled_elbo is None
