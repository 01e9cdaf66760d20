"""Train HUBS-GO on a Gymnasium env of one's own (docs/own_env.md).

    PYTHONPATH=examples python examples/own_env.py [--steps 20000] [--seed 0] [--out runs/corridor]

The env and the sub-goal predicates live in an importable module (corridor_env.py), so every `hubsgo`
command reads the run folder afterwards, e.g. `PYTHONPATH=examples hubsgo subgoals runs/corridor`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from corridor_env import make_corridor, switch_on

from hubsgo_ppl.experiments import train_env

# the critic spec: the human knows that one switch opens the goal, not which one
SPEC = {"name": "corridor-specific", "subgoals": ["switch_a", "switch_b", "goal"],
        "edges": [["switch_a", "goal", "positive"], ["switch_b", "goal", "positive"],
                  ["switch_a", "switch_b", "negative"]]}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="runs/corridor")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.KEY=VALUE")
    args = parser.parse_args(argv)
    summary = train_env(make_corridor, {"switch_a": {"fn": switch_on, "which": "a"},
                                        "switch_b": {"fn": switch_on, "which": "b"},
                                        "goal": {"kind": "goal"}},
                        model=SPEC, out=args.out, task="corridor", steps=args.steps, seed=args.seed,
                        max_episode_steps=60, overrides=args.overrides)
    top = json.loads((Path(args.out) / "subgoals.json").read_text())["ranking"][0]
    print(f"{summary['episodes']} episodes, {summary['env_steps']} env steps; G*: {top['subgoals']} at "
          f"P(sample) {top['prob']:.2f}")
    return summary


if __name__ == "__main__":
    main()
