"""scripts/critic_report.py: the stretch from the first success to 90% success, on a known log."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import pandas as pd
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "scripts"))
import critic_report  # noqa: E402  (a script module, not a package)


def _log(success: list[int], hubsgo: bool = True) -> pd.DataFrame:
    n = len(success)
    m = pd.DataFrame({"success": success, "length": [100 + i for i in range(n)],
                      "explore_eps": [1.0 - i / n for i in range(n)], "options": [10 + i % 3 for i in range(n)],
                      "low/revisits": [float(i) for i in range(n)]})
    if hubsgo:
        m["critic/set_size"] = [3.0] * n
        m["critic/kept"] = [float(i % 2) for i in range(n)]
    return m


def test_stretch_spans_the_first_success_to_the_first_full_window():
    # failures at episodes 0-4 and 10: the 20 episodes 4..23 first hold 18 successes (0.9), so the
    # stretch runs from episode 5 (the first success) to episode 23, 19 episodes with one failure
    success = [0] * 5 + [1] * 5 + [0] + [1] * 20
    out = critic_report._stretch(_log(success))
    assert out["stretch_episodes"] == 23 - 5
    assert out["stretch_success"] == pytest.approx(18 / 19)
    assert out["stretch_length"] == pytest.approx(sum(100 + i for i in range(5, 24)) / 19)
    assert out["stretch_eps"] == pytest.approx(1.0 - 5 / len(success))
    assert out["stretch_ghat"] == pytest.approx(3.0 + sum(i % 2 for i in range(5, 24)) / 19)
    assert out["stretch_options"] == pytest.approx(sum(10 + i % 3 for i in range(5, 24)) / 19)
    # revisits per option: the stretch's revisits over its options, not a mean of per-episode ratios
    assert out["stretch_revisits"] == pytest.approx(sum(range(5, 24)) / sum(10 + i % 3 for i in range(5, 24)))


def test_stretch_is_undefined_without_a_success_or_without_90_percent():
    assert all(math.isnan(v) for v in critic_report._stretch(_log([0] * 30)).values())
    assert all(math.isnan(v) for v in critic_report._stretch(_log([0, 1] * 20)).values())


def test_stretch_without_a_critic_has_no_ghat_size():
    # episodes 1..20 first hold 18 successes: the stretch is episodes 3..20
    out = critic_report._stretch(_log([0] * 3 + [1] * 25, hubsgo=False))
    assert out["stretch_episodes"] == 20 - 3 and math.isnan(out["stretch_ghat"])


def test_seeds_restricts_the_table_to_the_seeds_named(tmp_path, monkeypatch, capsys):
    # three h-DQN seeds whose logs reach 90% success at different steps; --seeds 0 2 averages seeds 0 and 2
    for seed, first in ((0, 2), (1, 10), (2, 4)):
        run = tmp_path / "keydoor" / "hdqn" / f"seed{seed}"
        run.mkdir(parents=True)
        m = _log([0] * first + [1] * 25, hubsgo=False)
        m["env_steps"] = [100 * (i + 1) for i in range(len(m))]
        m["return"], m["wall_time"] = m["success"] * 0.9, 1.0
        m.to_csv(run / "metrics.csv", index=False)
        (run / "learning_curve.png").write_bytes(b"")
    monkeypatch.setattr(sys, "argv", ["critic_report.py", str(tmp_path), "--seeds", "0", "2", "--no-eval"])
    critic_report.main()
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| keydoor | hdqn"))
    cells = [c.strip() for c in row.split("|")]
    # the first window of 20 episodes with 18 successes ends at episode 19 (seed 0) and 21 (seed 2)
    assert cells[3] == "2" and cells[5].startswith("2,100 ± 100")


@pytest.mark.parametrize("task", sorted(critic_report.ROUTES))
def test_every_route_names_sub_goals_of_its_maze(task):
    from hubsgo_ppl.envs import get_task

    names = set(get_task(task).catalogue.names)
    for route in critic_report.ROUTES[task]:
        assert route <= names and "goal" in route, (task, route - names)
