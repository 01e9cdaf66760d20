"""The notebooks in notebooks/: committed with the outputs of one complete smoke-size run (so that they
read on a code host without running), a first cell saying how to run them at full size, and each one
executing top to bottom at its smoke size (through nbmake, as CI does)."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOK_DIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NOTEBOOK_DIR.glob("*.ipynb"))
EXPECTED = {"01-critic-explained", "02-keydoor-walkthrough", "03-robustness", "04-mixed-initiative",
            "05-your-own-arm-task"}  # notebooks/README.md
# every notebook is committed with the outputs of a smoke-size run (notebooks/README.md)
EXECUTED = NOTEBOOKS


def _load(path: Path) -> dict:
    with path.open(encoding="utf-8") as fh:
        return json.load(fh)


def _source(cell: dict) -> str:
    src = cell.get("source", "")
    return "".join(src) if isinstance(src, list) else src


def _ids(paths):
    return [p.stem for p in paths]


def test_the_listed_notebooks_are_present():
    missing = EXPECTED - {p.stem for p in NOTEBOOKS}
    assert not missing, f"notebooks missing from {NOTEBOOK_DIR}: {sorted(missing)}"


@pytest.mark.parametrize("path", EXECUTED, ids=_ids(EXECUTED))
def test_committed_outputs_come_from_one_complete_run_and_name_no_machine_path(path):
    code = [c for c in _load(path)["cells"] if c["cell_type"] == "code"]
    counts = [c.get("execution_count") for c in code]
    assert counts == list(range(1, len(code) + 1)), (
        f"{path.name}: execution counts {counts}; execute it top to bottom before committing "
        f"(`.venv/bin/jupyter nbconvert --to notebook --execute --inplace {path.relative_to(ROOT)}`)")
    errors = [o for c in code for o in c.get("outputs", []) if o.get("output_type") == "error"]
    assert not errors, f"{path.name}: committed with an error output"
    text = json.dumps([c.get("outputs", []) for c in code])
    for prefix in ("/tmp/", "/home/", "/work/", "/root/", "/Users/", "site-packages"):
        assert prefix not in text, f"{path.name}: an output names a machine path ({prefix!r})"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_first_cell_says_how_to_run_at_full_size(path):
    cells = _load(path)["cells"]
    assert cells and cells[0]["cell_type"] == "markdown", f"{path.name}: the first cell must be markdown"
    intro = _source(cells[0])
    assert re.search(r"full size", intro, re.IGNORECASE), f"{path.name}: the first cell must say how to run at full size"
    # The switch it names (e.g. `FULL = True`) must be a parameter the notebook really defines.
    knobs = re.findall(r"`([A-Z][A-Z0-9_]*) = [^`]+`", intro)
    assert knobs, f"{path.name}: the first cell must name the parameter to change, e.g. `FULL = True`"
    code = "\n".join(_source(c) for c in cells if c["cell_type"] == "code")
    for knob in knobs:
        assert re.search(rf"^{knob}\s*=", code, re.MULTILINE), (
            f"{path.name}: the first cell names `{knob}` but no code cell assigns it"
        )


def _snapshot() -> set[str]:
    # nbmake runs each notebook with notebooks/ as its working directory, so relative writes land there
    return {str(p.relative_to(ROOT)) for p in NOTEBOOK_DIR.rglob("*") if ".ipynb_checkpoints" not in p.parts}


@pytest.mark.notebooks
@pytest.mark.parametrize("path", NOTEBOOKS, ids=_ids(NOTEBOOKS))
def test_notebook_runs_top_to_bottom_at_smoke_size(path):
    before = _snapshot()
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "--nbmake", "-q", "-p", "no:cacheprovider", str(path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, f"{path.name} failed under nbmake:\n{proc.stdout[-6000:]}\n{proc.stderr[-2000:]}"
    new = sorted(_snapshot() - before)
    assert not new, f"{path.name} wrote into the repository: {new}; write under tempfile.mkdtemp() instead"
