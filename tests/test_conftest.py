"""tests/conftest.py: without robosuite the arm tests skip with a reason, or, under HUBSGO_REQUIRE_ROBOSUITE=1
(``make test``), the run fails with one message."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARM_TESTS = "tests/envs/robosuite/test_gym_wrapper.py"


def _pytest_without_robosuite(tmp_path, *args, require):
    blocker = tmp_path / "block" / "robosuite"          # shadows the installed package, as if it were absent
    blocker.mkdir(parents=True)
    (blocker / "__init__.py").write_text(
        "raise ModuleNotFoundError(\"No module named 'robosuite' (blocked by the test)\", name='robosuite')\n")
    env = {k: v for k, v in os.environ.items() if k != "HUBSGO_REQUIRE_ROBOSUITE"}
    env["PYTHONPATH"] = os.pathsep.join([str(blocker.parent), env.get("PYTHONPATH", "")])
    if require:
        env["HUBSGO_REQUIRE_ROBOSUITE"] = "1"
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)


def test_required_robosuite_missing_fails_the_run_with_one_message(tmp_path):
    res = _pytest_without_robosuite(tmp_path, ARM_TESTS, require=True)
    assert res.returncode == 1, res.stdout[-2000:]
    out = res.stdout + res.stderr
    assert "HUBSGO_REQUIRE_ROBOSUITE=1" in out and "robosuite cannot be imported" in out
    assert "blocked by the test" in out
    assert " passed" not in out and " skipped" not in out


def test_missing_robosuite_skips_the_arm_tests_with_a_reason(tmp_path):
    res = _pytest_without_robosuite(tmp_path, ARM_TESTS, "tests/agents/test_flat.py::test_td3_trains_on_an_arm_task",
                                    "-rs", require=False)
    assert res.returncode == 0, res.stdout[-2000:]
    skipped = [line for line in res.stdout.splitlines() if line.startswith("SKIPPED")]
    assert len(skipped) == 2, res.stdout[-2000:]
    assert all("robosuite is not installed: the arm-task tests are skipped" in line for line in skipped)
