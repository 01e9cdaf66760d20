"""A prior or likelihood of the user's own, named in a critic spec as ``module:Class``
(examples/own_critic.py): imported and registered when the spec is read, in every process that reads
the run, and refused in one line where it cannot be."""

import itertools
import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
import yaml

from hubsgo_ppl.infer.critic import SubgoalCritic
from hubsgo_ppl.infer.likelihoods import LIKELIHOODS
from hubsgo_ppl.infer.priors import PRIORS
from hubsgo_ppl.specs import SpecError, load_model_spec

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
NAMES = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]


@pytest.fixture(autouse=True)
def _registries():
    """The registries as they were: other tests list the registered names."""
    saved = dict(PRIORS), dict(LIKELIHOODS)
    yield
    for table, before in zip((PRIORS, LIKELIHOODS), saved):
        table.clear()
        table.update(before)


def _spec(tmp_path, prior="own_critic:FewSubgoals", likelihood="own_critic:Cauchy"):
    path = tmp_path / "own.yaml"
    path.write_text(yaml.safe_dump({
        "name": "keydoor-own", "subgoals": NAMES,
        "edges": [["yellow_key", "yellow_door", "positive"], ["yellow_door", "goal", "positive"]],
        "prior": {"name": prior, "rate": 1.5}, "likelihood": {"name": likelihood, "scale": 0.2}}))
    return path


def test_the_critic_scores_every_set_with_the_users_prior_and_likelihood(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    critic = SubgoalCritic.from_spec(load_model_spec(str(_spec(tmp_path))), seed=0)
    assert type(critic.prior).__name__ == "FewSubgoals" and critic.prior.params() == {"rate": 1.5}
    assert type(critic.likelihood).__name__ == "Cauchy" and critic.likelihood.params() == {"scale": 0.2}
    states = torch.tensor(list(itertools.product([0.0, 1.0], repeat=len(NAMES))))
    exact = -1.5 * states.sum(-1) - len(NAMES) * math.log1p(math.exp(-1.5))     # normalised exp(-rate |w|)
    assert torch.allclose(critic.prior.distribution().log_prob(states), exact, atol=1e-5)
    assert torch.logsumexp(exact, 0).abs() < 1e-5
    r = torch.tensor([0.0, 0.2, -1.0])
    cauchy = -math.log(math.pi * 0.2) - torch.log1p((r / 0.2) ** 2)
    assert torch.allclose(critic.likelihood.distribution(r).log_prob(torch.zeros(())), cauchy, atol=1e-5)


@pytest.mark.parametrize("prior, likelihood, says", [
    ("own_critic:FewSubgoals", "own_critc:Cauchy", "likelihood 'own_critc:Cauchy': cannot import 'own_critc'"),
    ("own_critic:Cauchy", "own_critic:Cauchy", "prior 'own_critic:Cauchy' is a class, not a subclass of "
                                               "hubsgo_ppl.infer.Prior"),
    ("own_critic:FewSubgoals", "own_critic:Nope", "likelihood 'own_critic:Nope': module 'own_critic' has no 'Nope'"),
    ("own_critic:", "own_critic:Cauchy", "prior 'own_critic:': name a class of your own as 'module:Class'"),
])
def test_a_component_that_cannot_be_had_is_one_line_naming_the_file(tmp_path, monkeypatch, prior, likelihood, says):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    with pytest.raises(SpecError) as err:
        load_model_spec(str(_spec(tmp_path, prior, likelihood)))
    assert str(err.value).startswith(f"{tmp_path / 'own.yaml'}: ") and says in str(err.value), str(err.value)
    assert "\n" not in str(err.value)


def test_a_run_with_them_trains_and_is_read_again_only_where_they_import(tmp_path):
    run = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(EXAMPLES), os.environ.get("PYTHONPATH", "")])}

    def hubsgo(*argv, environ=env):
        return subprocess.run([sys.executable, "-m", "hubsgo_ppl.cli", *argv], capture_output=True, text=True,
                              timeout=300, env=environ, cwd=tmp_path)

    trained = hubsgo("train", "keydoor", "--model", str(_spec(tmp_path)), "--steps", "400", "--out", str(run))
    assert trained.returncode == 0, trained.stderr
    assert yaml.safe_load((run / "config.yaml").read_text())["model_spec"]["prior"]["name"] == "own_critic:FewSubgoals"
    assert hubsgo("evaluate", str(run), "--episodes", "1").returncode == 0
    without = {k: v for k, v in env.items() if k != "PYTHONPATH"}
    lost = hubsgo("evaluate", str(run), "--episodes", "1", environ=without)
    err = lost.stderr.strip().splitlines()
    assert lost.returncode == 2 and len(err) == 1 and "cannot import 'own_critic'" in err[0], lost.stderr
    assert "add its folder to PYTHONPATH" in err[0] and "Traceback" not in lost.stderr


def test_the_spec_of_docs_critic_names_the_examples_classes(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(EXAMPLES))
    text = (EXAMPLES.parent / "docs" / "critic.md").read_text()
    block = text.split("```yaml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "keydoor-own.yaml").write_text(block)
    spec = load_model_spec(str(tmp_path / "keydoor-own.yaml"))
    assert (spec.prior.name, spec.likelihood.name) == ("own_critic:FewSubgoals", "own_critic:Cauchy")
    assert type(SubgoalCritic.from_spec(spec, seed=0).prior).__name__ == "FewSubgoals"
