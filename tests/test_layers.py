"""The package layering: no import cycle between hubsgo_ppl's packages nor between its modules
(scripts/import_cycles.py)."""

import importlib.util
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "import_cycles.py"


def _load():
    spec = importlib.util.spec_from_file_location("import_cycles", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_no_import_cycle_between_packages():
    ic = _load()
    packages = ic.package_graph(ic.module_graph())
    assert "hubsgo_ppl.infer" in packages and "hubsgo_ppl.distributions" in packages
    assert ic.cycles(packages) == [], ic.cycles(packages)


def test_no_import_cycle_between_modules():
    """Every module of the package, however it imports (at module level or inside a function)."""
    ic = _load()
    modules = ic.module_graph()
    assert "hubsgo_ppl.agents.config" in modules and "hubsgo_ppl.agents.hiro" in modules
    assert ic.cycles(modules) == [], ic.cycles(modules)


def test_a_module_cycle_inside_one_package_is_found(tmp_path):
    ic = _load()
    pkg = tmp_path / "hubsgo_ppl"
    for name, text in {"__init__.py": "", "a/__init__.py": "", "a/config.py": "def f():\n    from .hiro import g\n",
                       "a/hiro.py": "from .config import f\n", "a/other.py": "from . import config\n"}.items():
        (pkg / name).parent.mkdir(parents=True, exist_ok=True)
        (pkg / name).write_text(text)
    modules = ic.module_graph(tmp_path)
    assert ic.cycles(ic.package_graph(modules)) == []                  # one package: no package cycle
    assert ic.cycles(modules) == [["hubsgo_ppl.a.config", "hubsgo_ppl.a.hiro"]]


def test_lower_layers_do_not_import_upper_ones():
    """graph -> distributions -> infer -> specs: each imports only from the ones before it."""
    packages = _load().package_graph(_load().module_graph())
    order = ["hubsgo_ppl.graph", "hubsgo_ppl.distributions", "hubsgo_ppl.infer", "hubsgo_ppl.specs"]
    for i, low in enumerate(order):
        assert not packages.get(low, set()) & set(order[i + 1:]), (low, packages[low])


def test_the_script_finds_a_cycle_and_exits_1(tmp_path):
    ic = _load()
    assert ic.cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    pkg = tmp_path / "hubsgo_ppl"
    for name, text in {"__init__.py": "", "x/__init__.py": "", "x/m.py": "def f():\n    from ..y import g\n",
                       "y/__init__.py": "", "y/n.py": "from hubsgo_ppl.x import m\n"}.items():
        (pkg / name).parent.mkdir(parents=True, exist_ok=True)
        (pkg / name).write_text(text)
    assert ic.cycles(ic.package_graph(ic.module_graph(tmp_path))) == [["hubsgo_ppl.x", "hubsgo_ppl.y"]]
    out = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    assert "package cycles: 0" in out.stdout and "module cycles: 0" in out.stdout
