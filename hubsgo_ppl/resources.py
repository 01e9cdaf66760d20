"""Where the shipped data lives: ``models/`` (critic specs), ``envs/`` (task catalogues, layouts), ``sweeps/``.

In a source checkout these are the top-level folders; after ``pip install .`` they ship inside the
package as ``hubsgo_ppl._models`` and ``hubsgo_ppl._envs`` (see ``[tool.setuptools]`` in pyproject).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

__all__ = ["models_dir", "envs_dir", "sweeps_dir"]

_REPO_ROOT = Path(__file__).resolve().parent.parent


def _shipped(package: str, fallback: str) -> Path:
    spec = importlib.util.find_spec(package)
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            p = Path(loc)
            if p.is_dir():
                return p
    return _REPO_ROOT / fallback


def models_dir() -> Path:
    """Folder of the built-in critic specs (``*.yaml``)."""
    return _shipped("hubsgo_ppl._models", "models")


def envs_dir() -> Path:
    """Folder of the built-in task catalogues (``*.yaml``) and their layouts/assets."""
    return _shipped("hubsgo_ppl._envs", "envs")


def sweeps_dir() -> Path:
    """Folder of the shipped sweep grids (``*.yaml``)."""
    return _shipped("hubsgo_ppl._sweeps", "sweeps")
