"""The critic's settings: one pydantic model (InferenceSpec) for specs and critics, one-line errors."""

import subprocess
import sys
import typing
from pathlib import Path

import pytest

from hubsgo_ppl.distributions.mh_kernels import KERNELS
from hubsgo_ppl.distributions.mrf import EXACT_LIMIT
from hubsgo_ppl.graph import SubgoalGraph
from hubsgo_ppl.infer.config import MAX_EXACT_N, InferenceConfig, InferenceSpec
from hubsgo_ppl.infer.critic import SubgoalCritic

FIELDS = ["lr", "burn_in", "num_samples", "kernel", "baseline_beta", "init_scale", "init", "exact_max_n",
          "pyro_validation", "jit"]


def test_the_restated_limits_are_the_distributions():
    assert typing.get_args(InferenceSpec.model_fields["kernel"].annotation) == KERNELS
    assert MAX_EXACT_N == EXACT_LIMIT


def test_config_is_the_spec_with_the_paper_defaults():
    cfg = InferenceConfig()
    assert isinstance(cfg, InferenceSpec)
    assert list(cfg.model_dump()) == FIELDS
    assert cfg.model_dump() == InferenceSpec().model_dump() == {
        "lr": 0.05, "burn_in": 32, "num_samples": 64, "kernel": "single_site", "baseline_beta": 0.9,
        "init_scale": 1.0, "init": "edges", "exact_max_n": 16, "pyro_validation": "first", "jit": True}
    assert InferenceConfig(burn_in=8.0, num_samples="16").burn_in == 8       # whole numbers are integers


@pytest.mark.parametrize("key, value", [
    ("lr", -1.0), ("lr", float("inf")), ("lr", float("nan")), ("burn_in", -1), ("burn_in", 1.5),
    ("num_samples", 1), ("kernel", "gibbs"), ("baseline_beta", 1.0), ("init_scale", float("nan")),
    ("init_scale", 1e39), ("init_scale", -1e10), ("init_scale", -0.5),
    ("exact_max_n", 21), ("init", "zeros"), ("pyro_validation", "sometimes"), ("jit", "yes"), ("jit", 1),
])
def test_bad_values_raise_one_line_naming_the_field(key, value):
    with pytest.raises(ValueError) as err:
        InferenceConfig(**{key: value})
    msg = str(err.value)
    assert msg.startswith(f"InferenceConfig.{key} = {value!r}: ") and "\n" not in msg, msg
    assert "default" in msg
    with pytest.raises(ValueError, match=key):            # pydantic's error, which specs format
        InferenceSpec(**{key: value})
    cfg = InferenceConfig()
    with pytest.raises(ValueError) as err:              # assignments are validated alike
        setattr(cfg, key, value)
    assert str(err.value).startswith(f"InferenceConfig.{key} = ") and "\n" not in str(err.value)
    assert cfg == InferenceConfig()


def test_unknown_setting_lists_the_valid_ones():
    with pytest.raises(ValueError, match=r"^InferenceConfig\.burnin: unknown setting; use one of: lr, burn_in"):
        InferenceConfig(burnin=3)


def test_critic_takes_a_spec_and_refuses_other_configs():
    graph = SubgoalGraph(["a", "b"], [("a", "b", 1)])
    critic = SubgoalCritic(graph, config=InferenceSpec(num_samples=8, burn_in=2), seed=0)
    critic.update(lambda w: 1.0 - w[..., :1])
    assert critic.last_samples().shape == (8, 2)
    assert critic.state_dict()["config"] == InferenceSpec(num_samples=8, burn_in=2).model_dump()
    with pytest.raises(TypeError, match="config must be an InferenceConfig"):
        SubgoalCritic(graph, config={"lr": 0.1})


def test_specs_import_no_torch():
    """specs nests InferenceSpec; importing specs must stay free of torch and Pyro."""
    code = "import sys, hubsgo_ppl.specs; print(sorted(m for m in ('torch', 'pyro') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[2])
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
