"""The critic's acceptance tables from a sweep folder (sweeps/critic_routes.yaml, critic_value.yaml).

For every task x variant over the seeds found: the mean return over training, the env steps until the
success rate over the last 20 episodes first reaches 0.9 ("never" counts are given), the env step of
the first success and the steps from it to 0.9 (an outcome critic acts only after the first success,
so HUBS-GO and h-DQN share everything before it), the greedy return
as a fraction of the BFS optimum (``hubsgo evaluate``, 5 episodes), and for HUBS-GO whether G*'s top
set is exactly one route (on the arm tasks: one consistent plan, ``PLANS``), with its probability and
the runner-up's. Mean ± s.e. over seeds.

``--after-first`` adds a second table on the stretch from a seed's first success to 90% success (the
episodes that close the 20-episode window): their number, success rate and mean length, the
high-level ε at the first success, and for HUBS-GO the mean size of Ĝt there (the critic's mode and
the safeguard's additions, ``critic/set_size`` + ``critic/kept`` of ``metrics.csv``), the options per
episode, and the low level's cycle-breaking random steps per option (``low/revisits`` over ``options``).

``--seeds`` restricts every table to those seeds (a table measured on seeds 0-4 of a sweep that now
runs more).

    python scripts/critic_report.py runs/sweeps/critic [--tasks keydoor threepair ...] [--seeds 0 1 2 3 4] [--no-eval] [--after-first]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import pandas as pd
from measure_common import episode_to, mean_se, steps_to  # a sibling script module

# The routes of the shipped key/door mazes and FourRoom: sub-goal sets G* may name, nothing else.
_PAIR = [["yellow_key", "yellow_door"], ["blue_key", "blue_door"]]
ROUTES = {
    "keydoor": [set(p + ["goal"]) for p in _PAIR],
    "threepair": [set(p + ["goal"]) for p in _PAIR + [["red_key", "red_door"]]],
    "twowall": [set(a + b + ["goal"]) for a in _PAIR for b in (["red_key", "red_door"], ["purple_key", "purple_door"])],
    "fourroom": [{"door_top", "door_right", "goal"}, {"door_left", "door_bottom", "goal"}],
    "vault": [set(p + ["green_door", "goal"]) for p in _PAIR],
    "detour": [{"red_key", "red_door", "goal"}, {"purple_key", "purple_door", "goal"}],
    "gallery": [{gap, "yellow_key", "yellow_door", "goal"} for gap in ("gap_north", "gap_south")],
    "moat": [{"green_key", "green_door", "goal"}, {"ford", "goal"}],
    "chain": [{"red_key", "red_door", "blue_key", "blue_door", "goal"}],
    "forge": [{"purple_key", "purple_door", "red_key", "red_door", "goal"},
              {"bridge", "grey_door", "red_key", "red_door", "goal"}],
}
ROUTES["vault_moved"] = ROUTES["vault"]


def routes(task: str) -> list[set[str]] | None:
    return ROUTES.get("keydoor" if task.startswith("keydoor_n") else task.removesuffix("_incorrect"))


# The arm tasks' consistent plans: a test on the top set rather than a list of sets, because the
# reach-above sub-goals are optional on the way (a grasp or a push starts above its cube anyway).
_STACK_CHAIN = {"grasp_red", "place_red_on_target", "grasp_green", "place_green_on_red"}


def _one_push(top: set[str]) -> bool:
    pushes = {n for n in top if n.startswith("push_")}
    if len(pushes) != 1:
        return False
    colour = next(iter(pushes)).split("_")[1]
    return pushes == {f"push_{colour}_to_{colour}"} and top - pushes <= {f"reach_{colour}"}


PLANS = {
    "stack_cubes": lambda top: _STACK_CHAIN <= top <= _STACK_CHAIN | {"reach_above_red", "reach_above_green"},
    "push_any_one": _one_push,
    "collect_three_balls": lambda top: top in ({"collect_ball_0", "collect_ball_1", "collect_ball_2"},
                                               {"collect_ball_3", "collect_ball_4", "collect_ball_5"}),
}


def consistent(task: str, top: set[str]) -> bool | None:
    """Whether G*'s top set is one route (mazes) or one consistent plan (arm tasks); None if unknown."""
    if task in PLANS:
        return PLANS[task](top)
    ok = routes(task)
    return None if ok is None else top in ok


def fmt(values) -> str:
    """``mean ± s.e.`` of the finite values, steps with thousands separators."""
    m, se = mean_se(values)
    if math.isnan(m):
        return "–"
    return f"{m:.4g} ± {se:.2g}" if abs(m) < 10 else f"{m:,.0f} ± {se:,.0f}"


def _stretch(m: pd.DataFrame) -> dict[str, float]:
    """The episodes from the first success to the one where the rolling success first reaches 0.9."""
    nan = {k: math.nan for k in ("stretch_episodes", "stretch_success", "stretch_length", "stretch_eps",
                                 "stretch_ghat", "stretch_options", "stretch_revisits")}
    success = m["success"].astype(float)
    i1 = episode_to(m.to_dict("records"))
    if not success.any() or i1 is None:
        return nan
    i0 = int(success.to_numpy().argmax())
    w = m.iloc[i0:i1 + 1]
    ghat = (float((w["critic/set_size"] + w["critic/kept"]).mean())
            if {"critic/set_size", "critic/kept"} <= set(m.columns) else math.nan)
    options = float(w["options"].mean()) if "options" in m.columns else math.nan
    # the low level's cycle-breaking random steps per option: how often it loops instead of reaching its sub-goal
    revisits = (float(w["low/revisits"].sum() / w["options"].sum())
                if {"options", "low/revisits"} <= set(m.columns) and w["options"].sum() > 0 else math.nan)
    return {"stretch_episodes": float(i1 - i0), "stretch_success": float(w["success"].mean()),
            "stretch_length": float(w["length"].mean()), "stretch_eps": float(w["explore_eps"].iloc[0]),
            "stretch_ghat": ghat, "stretch_options": options, "stretch_revisits": revisits}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("sweep_dir")
    ap.add_argument("--tasks", nargs="*")
    ap.add_argument("--seeds", nargs="*", type=int, help="only these seeds (default: every seed found)")
    ap.add_argument("--no-eval", action="store_true")
    ap.add_argument("--after-first", action="store_true", help="also the stretch from the first success to 90%%")
    args = ap.parse_args()
    root = Path(args.sweep_dir)
    wanted = None if args.seeds is None else {f"seed{k}" for k in args.seeds}
    rows = []
    for task_dir in sorted(p for p in root.iterdir() if p.is_dir()):
        if args.tasks and task_dir.name not in args.tasks:
            continue
        for var_dir in sorted(p for p in task_dir.iterdir() if p.is_dir()):
            for run in sorted(var_dir.glob("seed*")):
                if wanted is not None and run.name not in wanted:
                    continue
                if not (run / "subgoals.json").exists() and var_dir.name.startswith("hubsgo"):
                    continue
                m = pd.read_csv(run / "metrics.csv")
                if var_dir.name == "hdqn" and not (run / "learning_curve.png").exists():
                    continue
                first = float(m["env_steps"][m["success"].astype(bool).idxmax()]) if m["success"].any() else math.nan
                row = {"task": task_dir.name, "variant": var_dir.name, "seed": run.name,
                       "mean_return": float(m["return"].mean()), "steps90": steps_to(m.to_dict("records")),
                       "first": first, "wall": float(m["wall_time"].iloc[-1])}
                row["after_first"] = row["steps90"] - first
                row.update(_stretch(m))
                if not args.no_eval:
                    from hubsgo_ppl.experiments.run import evaluate

                    ev = evaluate(run, episodes=5)
                    row["greedy_frac"] = ev.get("fraction_of_optimal", math.nan)
                if (run / "subgoals.json").exists():
                    table = json.loads((run / "subgoals.json").read_text())
                    ranking = table.get("ranking") or table.get("top")
                    top = set(ranking[0]["subgoals"])
                    row["one_route"] = consistent(task_dir.name, top)
                    row["top"] = "{" + ", ".join(ranking[0]["subgoals"]) + "}"
                    row["p_top"], row["p_second"] = ranking[0]["prob"], ranking[1]["prob"] if len(ranking) > 1 else 0.0
                rows.append(row)
    df = pd.DataFrame(rows)
    print("| task | agent | seeds | mean return (training) | steps to 90% success | never | first success | "
          "90% after first success | greedy / BFS optimum | G* one route | p(top) | p(runner-up) | wall s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for (task, var), g in df.groupby(["task", "variant"], sort=False):
        one = g["one_route"].sum() if "one_route" in g and g["one_route"].notna().any() else None
        print(f"| {task} | {var} | {len(g)} | {fmt(list(g['mean_return']))} | {fmt(list(g['steps90']))} | "
              f"{int(g['steps90'].isna().sum())} | {fmt(list(g['first']))} | {fmt(list(g['after_first']))} | "
              f"{fmt(list(g.get('greedy_frac', pd.Series([math.nan]))))} | "
              f"{'' if one is None else f'{int(one)}/{len(g)}'} | "
              f"{fmt(list(g['p_top'])) if 'p_top' in g and g['p_top'].notna().any() else ''} | "
              f"{fmt(list(g['p_second'])) if 'p_second' in g and g['p_second'].notna().any() else ''} | "
              f"{fmt(list(g['wall']))} |")
    if args.after_first:
        print()
        print("| task | agent | episodes from the first success to 90% | their success rate | their mean length | "
              "high-level ε at the first success | size of Ĝt there | options per episode there | "
              "low-level revisits per option there |")
        print("|---|---|---|---|---|---|---|---|---|")
        for (task, var), g in df.groupby(["task", "variant"], sort=False):
            print(f"| {task} | {var} | {fmt(list(g['stretch_episodes']))} | {fmt(list(g['stretch_success']))} | "
                  f"{fmt(list(g['stretch_length']))} | {fmt(list(g['stretch_eps']))} | "
                  f"{fmt(list(g['stretch_ghat'])) if g['stretch_ghat'].notna().any() else ''} | "
                  f"{fmt(list(g['stretch_options']))} | {fmt(list(g['stretch_revisits']))} |")
    if "top" in df:
        print()
        for _, r in df[df["top"].notna()].iterrows():
            print(f"- {r['task']} {r['variant']} {r['seed']}: {r['top']} p {r['p_top']:.3f} (runner-up {r['p_second']:.3f})")


if __name__ == "__main__":
    main()
