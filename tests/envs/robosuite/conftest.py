"""Shared set-up of the arm-task tests: one env per task for the whole run (building one compiles its
MuJoCo model, about a second), and helpers that write object poses into the simulator.

Without robosuite the modules here are not collected, and the run's header says so (under
``make test``, HUBSGO_REQUIRE_ROBOSUITE=1 stops the run instead: tests/conftest.py)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

ROBOSUITE_MISSING = importlib.util.find_spec("robosuite") is None
if ROBOSUITE_MISSING:
    collect_ignore_glob = ["test_*.py"]


def pytest_report_header(config):
    if ROBOSUITE_MISSING:
        return "tests/envs/robosuite: not collected, robosuite is not installed (the `robosuite` extra)"
    return None

from hubsgo_ppl.resources import envs_dir


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
