"""The egocentric maze observation: its layout, its invariance to moving and turning a maze, and its
independence of the critic spec's sub-goal subset."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
import torch

from hubsgo_ppl.envs import make
from hubsgo_ppl.envs.minigrid import bfs
from hubsgo_ppl.envs.subset import make_subset

VIEW = 7


def _split(obs: np.ndarray, n: int):
    return obs[0], obs[1:1 + n], obs[1 + n:1 + 3 * n].reshape(n, 2), obs[1 + 3 * n:].reshape(2, VIEW, VIEW)


def test_keydoor_start_observation():
    env = make("keydoor", obs_mode="egocentric")
    obs, _ = env.reset(seed=0)
    carrying, achieved, offsets, window = _split(obs, 5)
    assert obs.shape == (1 + 3 * 5 + 2 * VIEW * VIEW,) and carrying == 0 and not achieved.any()
    # the agent at (1, 6) faces right (+x); its right is +y (down). Targets: yellow key (4, 3),
    # yellow door (8, 4), blue key (4, 9), blue door (8, 8), goal (11, 6)
    want = [(3, -3), (7, -2), (3, 3), (7, 2), (10, 0)]
    assert np.allclose(offsets * 13, want, atol=1e-5)
    # the row three cells ahead is x = 4, y = 3..9 from left to right: the two keys at its ends
    assert window[0, 0].tolist() == [1, 0, 0, 0, 0, 0, 1]
    # the rows behind the agent are the wall x = 0 and outside the grid
    assert window[0, 4:].min() == 1 and window[1].max() == 0


def test_turning_left_turns_the_offsets_and_the_window():
    env = make("keydoor", obs_mode="egocentric")
    env.reset(seed=0)
    obs, *_ = env.step(0)                       # turn left: now facing up (-y), its right is +x
    _, _, offsets, window = _split(obs, 5)
    assert np.allclose(offsets[0] * 13, (3, 3), atol=1e-5)       # yellow key: 3 ahead, 3 right
    assert window[0, :, 0].tolist() == [1] * VIEW                # the wall x = 0 on the agent's left
    env.step(1)
    env.step(2)
    env.step(2)
    env.step(2)                                 # back to facing right; forward to (4, 6)
    obs, *_ = env.step(0)                       # facing up at (4, 6): the yellow key 3 cells ahead
    _, _, offsets, window = _split(obs, 5)
    assert np.allclose(offsets[0] * 13, (3, 0), atol=1e-5) and window[0, 0, 3] == 1


def _write(tmp, name: str, rows: list[str], start_dir: str, cells: dict[str, tuple[int, int]]) -> str:
    (tmp / f"{name}.txt").write_text("\n".join(rows) + "\n")
    (tmp / f"{name}.yaml").write_text(textwrap.dedent(f"""\
        task: {name}
        family: minigrid
        options:
          layout: {name}.txt
          legend: {{y: {{type: key, color: yellow}}, Y: {{type: door, color: yellow, locked: true}}}}
          start_dir: {start_dir}
          max_steps: 400
        subgoals:
          - {{name: corner, kind: at, args: {{cell: {list(cells['corner'])}}}}}
          - {{name: yellow_key, kind: carrying, args: {{type: key, color: yellow}}}}
          - {{name: yellow_door, kind: door_open, args: {{color: yellow}}}}
          - {{name: goal, kind: goal}}
        """))
    return str(tmp / f"{name}.yaml")


def _turn(rows: list[str]) -> list[str]:
    """The layout turned a quarter clockwise on screen: (x, y) -> (H - 1 - y, x)."""
    h = len(rows)
    return ["".join(rows[h - 1 - xp][yp] for xp in range(h)) for yp in range(len(rows[0]))]


def test_a_moved_and_turned_maze_is_observed_alike(tmp_path):
    rows = ["#########",
            "#...#..G#",
            "#.y.#...#",
            "#...Y...#",
            "#A..#.~.#",
            "#...#...#",
            "#########"]
    turned = _turn(rows)
    assert len(turned) == 9 and len(turned[0]) == 7 and turned[1][2] == "A"
    a = make(_write(tmp_path, "a", rows, "right", {"corner": (1, 5)}), obs_mode="egocentric")
    b = make(_write(tmp_path, "b", turned, "down", {"corner": (1, 1)}), obs_mode="egocentric")
    oa, _ = a.reset(seed=0)
    ob, _ = b.reset(seed=0)
    plan = bfs.plan(make(str(tmp_path / "a.yaml"), seed=0), "goal")   # via the key and the door
    rng = np.random.default_rng(3)
    actions = plan + [int(x) for x in rng.integers(5, size=400)]
    seen_carry = seen_open = False
    for act in actions:
        np.testing.assert_array_equal(oa, ob)
        oa, ra, ta, ua, ia = a.step(act)
        ob, rb, tb, ub, ib = b.step(act)
        assert (ra, ta, ua) == (rb, tb, ub) and np.array_equal(ia["subgoals"], ib["subgoals"])
        seen_carry |= bool(ia["subgoals"][1])
        seen_open |= bool(ia["subgoals"][2])
        if ta or ua:
            oa, _ = a.reset(seed=0)
            ob, _ = b.reset(seed=0)
    assert seen_carry and seen_open and len(plan) > 10


def test_a_subset_of_the_subgoals_keeps_the_observation():
    full = make("keydoor_incorrect", obs_mode="egocentric")
    sub = make_subset("keydoor_incorrect", ["yellow_key", "yellow_door", "goal"], obs_mode="egocentric")
    assert full.observation_space.shape == sub.observation_space.shape == (1 + 3 * 9 + 2 * VIEW * VIEW,)
    of, _ = full.reset(seed=0)
    os_, _ = sub.reset(seed=0)
    rng = np.random.default_rng(0)
    phi_full, phi_sub = full.unwrapped.subgoal_potential(), sub.unwrapped.subgoal_potential()
    for _ in range(200):
        np.testing.assert_array_equal(of, os_)
        pf = phi_full(torch.as_tensor(of)[None])[0]
        ps = phi_sub(torch.as_tensor(os_)[None])[0]
        assert ps.tolist() == pf[[0, 1, 4]].tolist()
        act = int(rng.integers(5))
        of, _, t, u, _ = full.step(act)
        os_, *_ = sub.step(act)
        if t or u:
            of, _ = full.reset(seed=0)
            os_, _ = sub.reset(seed=0)


@pytest.mark.parametrize("task", ["keydoor", "fourroom"])
def test_egocentric_potential_equals_the_symbolic_one(task):
    ego, sym = make(task, obs_mode="egocentric"), make(task)
    phi_e, phi_s = ego.unwrapped.subgoal_potential(), sym.unwrapped.subgoal_potential()
    oe, _ = ego.reset(seed=1)
    os_, _ = sym.reset(seed=1)
    rng = np.random.default_rng(1)
    compared = 0
    for _ in range(300):
        if ego.unwrapped.carrying is None:   # a carried key's target is the agent's cell, not its catalogue cell
            got = phi_e(torch.as_tensor(oe)[None])[0]
            want = phi_s(torch.as_tensor(os_)[None])[0]
            assert got.tolist() == pytest.approx(want.tolist(), abs=1e-6)
            compared += 1
        act = int(rng.integers(ego.action_space.n))
        oe, _, t, u, _ = ego.step(act)
        os_, *_ = sym.step(act)
        if t or u:
            oe, _ = ego.reset(seed=2)
            os_, _ = sym.reset(seed=2)
    assert compared > 100
