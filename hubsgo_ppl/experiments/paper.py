"""The numbers the paper reports in its Tables 1 and 2, beside which `hubsgo report` prints a sweep's."""

from __future__ import annotations

__all__ = ["PAPER"]

#: The paper's reported numbers (mean, s.e.) by table, row label and task.
PAPER: dict[str, dict[str, dict[str, tuple[float, float]]]] = {
    "table1": {
        "HUBS-GO (specific correlations)": {"fourroom": (0.8904, 0.0044), "keydoor": (0.8763, 0.0053),
                                            "stack_cubes": (0.8891, 0.0152), "push_any_one": (0.9173, 0.0123),
                                            "collect_three_balls": (0.9627, 0.0099)},
        "HUBS-GO (fully connected)": {"fourroom": (0.8416, 0.0879), "keydoor": (0.8580, 0.0999),
                                      "stack_cubes": (0.8563, 0.1026), "push_any_one": (0.9095, 0.0125),
                                      "collect_three_balls": (0.9370, 0.0190)},
        "HUBS-GO (fully independent)": {"fourroom": (0.7114, 0.1196), "keydoor": (0.7425, 0.0723),
                                        "stack_cubes": (0.8209, 0.1072), "push_any_one": (0.8744, 0.1154),
                                        "collect_three_balls": (0.8467, 0.1380)},
        "DDQN": {"fourroom": (0.1899, 0.0077), "keydoor": (0.2107, 0.0109)},
        "PPO": {"fourroom": (0.6664, 0.0083), "keydoor": (0.7567, 0.0084), "stack_cubes": (0.3934, 0.0068),
                "push_any_one": (0.3337, 0.0114), "collect_three_balls": (0.3122, 0.0116)},
        "TD3": {"stack_cubes": (0.4890, 0.0045), "push_any_one": (0.6903, 0.0144),
                "collect_three_balls": (0.6407, 0.0159)},
        "hDQN": {"fourroom": (0.4287, 0.0166), "keydoor": (0.4584, 0.0126)},
        "HIRO": {"fourroom": (0.8250, 0.0054), "keydoor": (0.8332, 0.0064), "stack_cubes": (0.7820, 0.0141),
                 "push_any_one": (0.8730, 0.0094), "collect_three_balls": (0.8514, 0.0193)},
        "HIGL": {"fourroom": (0.8447, 0.0172), "keydoor": (0.5439, 0.0210), "stack_cubes": (0.8105, 0.0121),
                 "push_any_one": (0.8553, 0.0209), "collect_three_balls": (0.6274, 0.0041)},
    },
    "table2": {
        "HUBS-GO (specific sub-goals)": {"fourroom": (0.8904, 0.0044), "keydoor": (0.8763, 0.0053)},
        "HUBS-GO (incorrect sub-goals)": {"fourroom": (0.7629, 0.0163), "keydoor": (0.7274, 0.0123)},
        "h-DQN (specific sub-goals)": {"fourroom": (0.4287, 0.0166), "keydoor": (0.4584, 0.0126)},
        "h-DQN (incorrect sub-goals)": {"fourroom": (0.2438, 0.0068), "keydoor": (0.1430, 0.0072)},
        "HIGL": {"fourroom": (0.8447, 0.0172), "keydoor": (0.5439, 0.0210)},
        "HIRO": {"fourroom": (0.8250, 0.0054), "keydoor": (0.8332, 0.0064)},
    },
}


def _cardinal_rows(rows: dict[str, dict[str, tuple[float, float]]]) -> dict[str, dict[str, tuple[float, float]]]:
    """The paper's maze baselines most likely ran with the cardinal action set (docs/mazes.md): the rows
    run on it stand beside the paper's rows of the same agent."""
    agents = {"HUBS-GO (specific, cardinal actions)": "HUBS-GO (specific correlations)",
              "hDQN (cardinal actions)": "hDQN", **{f"{a} (cardinal actions)": a for a in ("HIRO", "HIGL", "PPO")}}
    return {label: {t: rows[agent][t] for t in ("fourroom", "keydoor")} for label, agent in agents.items()
            if agent in rows}


PAPER = {table: rows | _cardinal_rows(rows) for table, rows in PAPER.items()}
