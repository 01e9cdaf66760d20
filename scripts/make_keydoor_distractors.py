"""Write the KeyDoor mazes with N = 9, 17, 33 and 65 candidate sub-goals (envs/keydoor_n*.yaml) and
their critic specs (models/keydoor_n*-specific.yaml).

Each adds ``at`` sub-goals to KeyDoor's five: first the four misleading room corners, then floor cells
drawn (seeded) from those off every plan within two steps of the optimum, so no distractor lies on or
beside either route. The sets are nested (N = 17's cells are N = 33's first ones). Run from the
repository root: ``python scripts/make_keydoor_distractors.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hubsgo_ppl.envs.minigrid.bfs import shortest_path_cells

ROOT = Path(__file__).resolve().parents[1]
CORNERS = [("corner_nw", (1, 1)), ("corner_sw", (1, 11)), ("corner_ne", (11, 1)), ("corner_se", (11, 11))]
SIZES = (9, 17, 33, 65)

CATALOGUE = """\
# KeyDoor with {k} distractor sub-goals (N = {n}), written by scripts/make_keydoor_distractors.py:
# KeyDoor's five sub-goals, then 'at' cells off every plan within two steps of the optimum (the four
# room corners first). Same layout, legend and budget as keydoor.yaml.
task: keydoor_n{n}
title: KeyDoor-N{n}
family: minigrid
description: >-
  KeyDoor (either key-door pair opens a route to the goal) with {k} misleading 'agent at cell'
  sub-goals off both routes.
options:
  layout: keydoor.txt
  legend:
    y: {{type: key, color: yellow}}
    Y: {{type: door, color: yellow, locked: true}}
    b: {{type: key, color: blue}}
    B: {{type: door, color: blue, locked: true}}
  max_steps: 2000
  start_dir: right
  actions: [left, right, forward, pickup, toggle]
  mission: open a door with the key of its colour, then reach the goal
subgoals:
  - {{name: yellow_key, kind: carrying, args: {{type: key, color: yellow}}, description: carrying the yellow key}}
  - {{name: yellow_door, kind: door_open, args: {{color: yellow}}, description: the yellow door is open}}
  - {{name: blue_key, kind: carrying, args: {{type: key, color: blue}}, description: carrying the blue key}}
  - {{name: blue_door, kind: door_open, args: {{color: blue}}, description: the blue door is open}}
  - {{name: goal, kind: goal, description: the agent is on the goal}}
"""

SPEC = """\
# Critic spec for keydoor_n{n} in the default style: KeyDoor's human edges; the distractors get none.
name: keydoor_n{n}-specific
task: keydoor_n{n}
subgoals: [{names}]
graph: specific
edges:
  - [yellow_key, yellow_door, positive]
  - [blue_key, blue_door, positive]
  - [yellow_key, blue_key, negative]
  - [yellow_door, blue_door, negative]
  - [yellow_door, goal, positive]
  - [blue_door, goal, positive]
prior: {{name: ising, strength: 3.0, field: -2.0}}
likelihood: {{name: outcome, flip: 0.02}}
inference: {{lr: 0.05, burn_in: 32, num_samples: 64, kernel: single_site, baseline_beta: 0.9, init: prior}}
"""


def distractor_cells() -> list[tuple[str, tuple[int, int]]]:
    rows = [r for r in (ROOT / "envs" / "keydoor.txt").read_text().splitlines() if not r.startswith(";")]
    near = shortest_path_cells(ROOT / "envs" / "keydoor.yaml", slack=2)
    corners = {c for _, c in CORNERS}
    free = [(x, y) for y, row in enumerate(rows) for x, ch in enumerate(row)
            if ch == "." and (x, y) not in near and (x, y) not in corners]
    order = np.random.default_rng(0).permutation(len(free))
    cells = CORNERS + [(f"cell_{free[i][0]}_{free[i][1]}", free[i]) for i in order]
    if len(cells) < max(SIZES) - 5:
        raise SystemExit(f"only {len(cells)} distractor cells off the routes; need {max(SIZES) - 5}")
    return cells


def main() -> None:
    cells = distractor_cells()
    for n in SIZES:
        extra = cells[: n - 5]
        text = CATALOGUE.format(n=n, k=n - 5) + "".join(
            f"  - {{name: {name}, kind: at, args: {{cell: [{x}, {y}]}}, description: \"misleading: cell ({x}, {y})\"}}\n"
            for name, (x, y) in extra)
        (ROOT / "envs" / f"keydoor_n{n}.yaml").write_text(text)
        names = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"] + [name for name, _ in extra]
        (ROOT / "models" / f"keydoor_n{n}-specific.yaml").write_text(SPEC.format(n=n, names=", ".join(names)))
        print(f"keydoor_n{n}: {n} sub-goals")


if __name__ == "__main__":
    main()
