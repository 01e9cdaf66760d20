"""Shared test set-up: the robosuite requirement, and a recorder of the episodes an env plays.

robosuite (the arm tasks) is an optional extra. Without it the arm suite is skipped, with the reason
shown in the summary (``-ra``). ``make test`` promises the arm suite and sets HUBSGO_REQUIRE_ROBOSUITE=1:
then a robosuite that cannot be imported stops the whole run with exit status 1 and one message,
instead of a green run that silently skipped every arm test.
"""

from __future__ import annotations

import functools
import importlib
import os
from typing import Any

import pytest

REQUIRE_ROBOSUITE = "HUBSGO_REQUIRE_ROBOSUITE"
ROBOSUITE_SKIP = ("robosuite is not installed: the arm-task tests are skipped (install the `robosuite` extra; "
                  f"`make test` sets {REQUIRE_ROBOSUITE}=1 and fails instead)")


@functools.lru_cache(maxsize=None)
def _robosuite_import_error() -> str | None:
    """None if robosuite imports, else the error (imported at most once per run). Imported through the
    package, whose logging filter then drops robosuite's installation notices from the test output too."""
    try:
        importlib.import_module("hubsgo_ppl.envs.robosuite")
    except Exception as exc:  # noqa: BLE001 - any failure to import is reported as it is
        return f"{type(exc).__name__}: {exc}"
    return None


def pytest_sessionstart(session: pytest.Session) -> None:
    if os.environ.get(REQUIRE_ROBOSUITE) != "1":
        return
    error = _robosuite_import_error()
    if error is not None:
        pytest.exit(f"{REQUIRE_ROBOSUITE}=1 (the arm-task suite is required) but robosuite cannot be imported "
                    f"({error}); install it with `make install` (the `robosuite` extra) or unset "
                    f"{REQUIRE_ROBOSUITE} to skip the arm tests", returncode=1)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Tests marked ``mujoco`` in modules that import without robosuite are skipped when it is missing
    (the arm-test modules themselves skip through ``pytest.importorskip``)."""
    marked = [item for item in items if item.get_closest_marker("mujoco") is not None]
    if not marked or os.environ.get(REQUIRE_ROBOSUITE) == "1" or _robosuite_import_error() is None:
        return
    skip = pytest.mark.skip(reason=ROBOSUITE_SKIP)
    for item in marked:
        item.add_marker(skip)


@pytest.fixture
def record_episodes(monkeypatch):
    """Episodes played by the envs that ``hubsgo_ppl.experiments.run.load_run`` builds (``evaluate``'s),
    recorded from the env's own ``step`` results, independently of the agents' bookkeeping.

    Yields a list of dicts, one per episode with at least one step: ``return`` (sum of rewards),
    ``length`` (steps), ``success`` (the last step's ``info["is_success"]``), ``terminated``,
    ``truncated`` and ``max_steps`` (the env's ``max_steps`` or ``horizon``)."""
    import hubsgo_ppl.experiments.run as run_mod

    episodes: list[dict[str, Any]] = []
    real_load_run = run_mod.load_run

    def load_run(*args, **kwargs):
        resolved, env, agent, ckpt = real_load_run(*args, **kwargs)
        real_step, real_reset = env.step, env.reset
        limit = getattr(env.unwrapped, "max_steps", None) or getattr(env.unwrapped, "horizon", None)
        current: dict[str, Any] = {}

        def reset(*a, **kw):
            current.clear()
            current.update({"return": 0.0, "length": 0, "success": False, "terminated": False,
                            "truncated": False, "max_steps": limit})
            return real_reset(*a, **kw)

        def step(action):
            obs, reward, terminated, truncated, info = real_step(action)
            if current["length"] == 0:
                episodes.append(current.copy())
            current["return"] += float(reward)
            current["length"] += 1
            current.update(success=bool(info.get("is_success", False)), terminated=bool(terminated),
                           truncated=bool(truncated))
            episodes[-1] = dict(current)
            return obs, reward, terminated, truncated, info

        env.step, env.reset = step, reset
        return resolved, env, agent, ckpt

    monkeypatch.setattr(run_mod, "load_run", load_run)
    return episodes
