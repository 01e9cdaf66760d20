"""The notebooks plot the critic's marginals over training from critic_history.csv: its training rows,
and only the sub-goal columns (its ``critic`` column names the critic of each row, text, not a marginal)."""

import json
from pathlib import Path

import pytest

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))


def _cells_reading_history(path):
    sources = ["".join(c["source"]) for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]
    return [s for s in sources if "critic_history.csv" in s]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_marginals_over_training_read_the_training_rows_only(path):
    for source in _cells_reading_history(path):
        assert '["critic"] == "training"' in source, f"{path.name}: a cell plots critic_history.csv whole"
        for line in source.splitlines():
            if "history.columns" in line:
                assert '"critic"' in line, f"{path.name}: {line.strip()} takes the critic column for a sub-goal"
