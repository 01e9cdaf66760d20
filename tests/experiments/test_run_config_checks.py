"""A RunConfig given from Python is refused in one line (a RunError), as the command line refuses its flags."""

import pytest

from hubsgo_ppl.experiments import RunConfig, RunError, train
from hubsgo_ppl.experiments.resolve import resolve_run


def test_an_unknown_agent_is_refused_before_anything_is_built():
    with pytest.raises(RunError, match="unknown agent 'hubsg'; use one of: .*hubsgo"):
        resolve_run(RunConfig(task="keydoor", agent="hubsg", steps=100))
