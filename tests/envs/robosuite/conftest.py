"""Shared set-up of the arm-task tests: one env per task for the whole run (building one compiles its
MuJoCo model, about a second), and helpers that write object poses into the simulator.

Without robosuite every module here is skipped as a whole, with the reason (under ``make test``,
HUBSGO_REQUIRE_ROBOSUITE=1 stops the run instead: tests/conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hubsgo_ppl.resources import envs_dir


def _robosuite_missing() -> bool:
    try:
        import robosuite  # noqa: F401
    except Exception:  # noqa: BLE001 - any failure to import counts as missing
        return True
    return False


ROBOSUITE_MISSING = _robosuite_missing()
SKIP_REASON = ("robosuite is not installed: the arm-task tests are skipped (install the `robosuite` extra; "
               "`make test` sets HUBSGO_REQUIRE_ROBOSUITE=1 and fails instead)")


class _SkippedModule(pytest.Module):
    """A test module of this folder when robosuite is missing: skipped as a whole, with the reason."""

    def collect(self):
        pytest.skip(SKIP_REASON)


def pytest_pycollect_makemodule(module_path, parent):
    if ROBOSUITE_MISSING:
        return _SkippedModule.from_parent(parent, path=module_path)
    return None


@pytest.fixture(scope="session")
def catalogue():
    """task -> path of its shipped catalogue."""
    return lambda task: str(envs_dir() / f"{task}.yaml")


@pytest.fixture(scope="session")
def arm_env(catalogue):
    """task -> its (shared) env, reset with seed 0."""
    from hubsgo_ppl.envs.robosuite import make_robosuite_task

    cache: dict = {}

    def get(task: str):
        if task not in cache:
            cache[task] = make_robosuite_task(catalogue(task))
        cache[task].reset(seed=0)
        return cache[task]

    yield get
    for env in cache.values():
        env.close()


@pytest.fixture(scope="session")
def put():
    def put(env, name: str, xyz) -> None:
        """Write an object's pose (upright) into the sim and recompute positions and contacts."""
        t = env.unwrapped.task
        t.sim.data.set_joint_qpos(t.objects[name].joints[0], np.r_[xyz, 1.0, 0.0, 0.0, 0.0])
        t.sim.data.qvel[:] = 0.0
        t.sim.forward()

    return put


@pytest.fixture(scope="session")
def achieved():
    def achieved(env) -> dict[str, bool]:
        return dict(zip(env.unwrapped.subgoal_names, env.unwrapped.subgoal_achieved().tolist()))

    return achieved
