"""`pip install .` (not only editable) ships the built-in specs, task catalogues and sweeps."""

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_wheel_contains_models_envs_and_sweeps(tmp_path):
    res = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q",
                          str(ROOT), "-w", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    wheel = next(tmp_path.glob("hubsgo_ppl-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for f in ROOT.glob("models/*.yaml"):
        assert f"hubsgo_ppl/_models/{f.name}" in names
    for f in list(ROOT.glob("envs/*.yaml")) + list(ROOT.glob("envs/*.txt")):
        assert f"hubsgo_ppl/_envs/{f.name}" in names
    for f in ROOT.glob("sweeps/*.yaml"):
        assert f"hubsgo_ppl/_sweeps/{f.name}" in names
    code = {n for n in names if n.endswith(".py")}
    for f in (ROOT / "hubsgo_ppl").rglob("*.py"):
        assert f"hubsgo_ppl/{f.relative_to(ROOT / 'hubsgo_ppl').as_posix()}" in code, f
