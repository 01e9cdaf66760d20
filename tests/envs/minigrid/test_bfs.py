"""BFS optimal plans: hand-checked step counts, plans that really work in the env, and a symbolic
transition model that matches MiniGrid step for step."""

from __future__ import annotations

import inspect
import textwrap
from dataclasses import replace

import numpy as np
import pytest

from hubsgo_ppl.envs import make
from hubsgo_ppl.envs.minigrid import bfs
from hubsgo_ppl.envs.minigrid.bfs import optimal_steps
from hubsgo_ppl.envs.minigrid.layout import load_maze_spec
from hubsgo_ppl.resources import envs_dir
from hubsgo_ppl.specs import SpecError


def _user_task(tmp_path, layout, actions="[left, right, forward, pickup, drop, toggle, done]",
               start_dir="right", max_steps=200, extra_subgoals=""):
    (tmp_path / "u.txt").write_text(layout)
    path = tmp_path / "u.yaml"
    path.write_text(textwrap.dedent(f"""\
        task: u
        family: minigrid
        options:
          layout: u.txt
          legend:
            y: {{type: key, color: yellow}}
            r: {{type: key, color: red}}
            o: {{type: ball, color: green}}
            Y: {{type: door, color: yellow, locked: true}}
            R: {{type: door, color: red, locked: true}}
            d: {{type: door, color: blue}}
          max_steps: {max_steps}
          start_dir: {start_dir}
          actions: {actions}
        subgoals:
          - {{name: goal, kind: goal}}
        """) + extra_subgoals)
    return path


def test_keydoor_optimal_steps_hand_checked():
    # (1,6) facing right: 3 fwd to (4,6), turn up, 2 fwd to (4,4), pickup (4,3), turn right,
    # 3 fwd to (7,4), toggle, 4 fwd to (11,4), turn down, 2 fwd to (11,6): 19 steps.
    assert bfs.optimal_steps("keydoor") == 19
    assert bfs.optimal_return("keydoor") == pytest.approx(1 - 0.9 * 19 / 2000, abs=1e-12)
    # the two key-door routes are mirror images about y=6, so a plan via either key is optimal
    assert bfs.optimal_steps("keydoor_incorrect") == 19


def test_fourroom_optimal_steps_hand_checked():
    # facing right: 2 fwd, turn down, 8 fwd to (3,9) via door_left, turn left (east), 8 fwd to
    # (11,9) via door_bottom, turn down, 2 fwd: 20 moves + 3 turns = 23; facing down is the mirror
    # image via door_top/door_right; facing left or up costs one extra turn.
    assert [bfs.optimal_steps("fourroom", start_dir=d) for d in range(4)] == [23, 23, 24, 24]
    # the start direction is random, so the optimal return is the mean over the four headings
    expected = np.mean([1 - 0.9 * n / 1000 for n in (23, 23, 24, 24)])
    assert bfs.optimal_return("fourroom") == pytest.approx(expected, abs=1e-12)
    with pytest.raises(ValueError, match="start direction is random"):
        bfs.optimal_steps("fourroom")


@pytest.mark.parametrize("task, seed", [("keydoor", 0), ("fourroom", 3), ("keydoor_incorrect", 1),
                                        ("fourroom_incorrect", 5)])
def test_following_the_plan_reaches_goal_with_predicted_reward(task, seed):
    env = make(task, seed=seed)
    predicted = bfs.optimal_return(env)
    actions = bfs.plan(env)
    total, terminated, info = 0.0, False, {}
    for i, a in enumerate(actions):
        assert not terminated, "the plan continues after the episode ended"
        _, r, terminated, truncated, info = env.step(a)
        total += r
        assert not truncated
    assert terminated and info["is_success"]
    assert total == pytest.approx(predicted, abs=1e-12)
    assert total == pytest.approx(1 - 0.9 * len(actions) / env.max_steps, abs=1e-12)


def test_plan_from_mid_episode_counts_steps_taken():
    env = make("keydoor", seed=0)
    for a in (0, 0, 1):  # turn left, left, right: 3 wasted steps, now facing up
        env.step(a)
    assert bfs.optimal_return(env) == pytest.approx(1 - 0.9 * (3 + bfs.optimal_steps(env)) / 2000)
    # the state is the start facing up: 2 fwd, turn right, 3 fwd to (4,4), turn left, pickup,
    # turn right, 3 fwd, toggle, 4 fwd, turn down, 2 fwd = 20, as planning from the catalogue says
    assert bfs.optimal_steps(env) == 20 == bfs.optimal_steps("keydoor", start_dir=3)


def test_plan_to_subgoal_names_and_indices():
    spec = load_maze_spec(envs_dir() / "keydoor.yaml")
    a = bfs.plan(spec, "yellow_key")
    assert a == bfs.plan(spec, 0)
    assert spec.options.actions[a[-1]] == "pickup"
    with pytest.raises(SpecError, match="no sub-goal 'red_key'; use one of: yellow_key"):
        bfs.plan(spec, "red_key")
    with pytest.raises(IndexError, match="out of range"):
        bfs.plan(spec, 7)


def test_unreachable_goal_and_zero_return(tmp_path):
    walled = _user_task(tmp_path, "######\n#A.#G#\n######\n")
    with pytest.raises(ValueError, match="unreachable"):
        bfs.optimal_steps(walled)
    assert bfs.optimal_return(walled) == 0.0


def test_check_reachable_refuses_an_unreachable_goal_and_names_unreachable_subgoals(tmp_path):
    with pytest.raises(SpecError, match=r"the goal \(4, 1\) cannot be reached from the start \(1, 1\)"):
        bfs.check_reachable(_user_task(tmp_path, "######\n#A.#G#\n######\n"))
    # the yellow key lies behind its own door: the door and the goal beyond it are out of reach
    with pytest.raises(SpecError, match="cannot be reached"):
        bfs.check_reachable(_user_task(tmp_path, "#######\n#A.Yy.#\n#####G#\n#######\n"))
    # the red key is walled in: the goal is reachable, the red key never held
    key = "  - {name: red_key, kind: carrying, args: {type: key, color: red}}\n"
    cell = "  - {name: corner, kind: at, args: {cell: [5, 2]}}\n"
    path = _user_task(tmp_path, "#######\n#A...G#\n###.#r#\n#######\n", extra_subgoals=key + cell)
    assert bfs.check_reachable(path) == ["red_key", "corner"]
    # past max_states the relaxation still finds both, and still refuses the walled-off goal
    assert bfs.check_reachable(path, max_states=1) == ["red_key", "corner"]
    with pytest.raises(SpecError, match="cannot be reached"):
        bfs.check_reachable(_user_task(tmp_path, "######\n#A.#G#\n######\n"), max_states=1)
    # where it finds nothing wrong, the maze is not checked
    assert bfs.check_reachable(_user_task(tmp_path, "######\n#A..G#\n######\n"), max_states=1) is None


def _states(path, actions=None, put_back=False):
    """How many states a whole search from the start visits (with ``actions`` in place of the task's;
    ``put_back``: dropping only on an object's starting cell)."""
    spec = load_maze_spec(path)
    if actions is not None:
        spec = replace(spec, options=spec.options.model_copy(update={"actions": actions}))
    seen = set()
    bfs._bfs(spec, spec.initial_state(0), lambda s: seen.add(s) or False, max_states=10**9, put_back=put_back)
    return len(seen)


def test_with_a_drop_action_the_check_first_searches_without_it(tmp_path):
    """A dropped key may lie on any free cell, which multiplies the states; the states reached without
    ``drop`` are reachable with it, so a maze that passes without it is checked within a small cap."""
    key = "  - {name: yellow_key, kind: carrying, args: {type: key, color: yellow}}\n"
    room = "########\n#A.....#\n#..y...#\n#......#\n#####Y##\n#....G.#\n########\n"
    path = _user_task(tmp_path, room, extra_subgoals=key)
    small, whole = _states(path, ["left", "right", "forward", "pickup", "toggle", "done"]), _states(path)
    assert whole > 5 * small
    assert bfs.check_reachable(path, max_states=small + 10) == []
    assert bfs.check_reachable(path, max_states=small // 2) is None
    # a walled-in red key: the search without drop misses it, and so does the relaxation, so that search
    # answers exactly; past every cap the relaxation alone still names it
    red = "  - {name: red_key, kind: carrying, args: {type: key, color: red}}\n"
    pocket = "#########\n#A....#r#\n#..y..###\n#.......#\n######Y##\n#....G..#\n#########\n"
    walled = _user_task(tmp_path, pocket, extra_subgoals=key + red)
    small = _states(walled, ["left", "right", "forward", "pickup", "toggle", "done"])
    assert bfs.check_reachable(walled, max_states=small + 10) == ["red_key"]
    assert bfs.check_reachable(walled, max_states=small // 2) == ["red_key"]
    assert bfs.check_reachable(walled) == ["red_key"]
    # here the red key blocks the corridor and must be put down behind the agent before the yellow one
    # can be picked up: only the whole search reaches the goal
    corridor = _user_task(tmp_path, "########\n#Ar.yYG#\n########\n", extra_subgoals=key + red)
    assert bfs.check_reachable(corridor) == []
    with pytest.raises(SpecError, match="cannot be reached"):
        bfs.check_reachable(_user_task(tmp_path, "########\n#Ar.yYG#\n########\n",
                                       actions="[left, right, forward, pickup, toggle]"))
    # no door on the way, only lava: the message blames the walls and lava, not a key
    with pytest.raises(SpecError, match="walls or lava cut the start off from the goal; open a gap"):
        bfs.check_reachable(_user_task(tmp_path, "#######\n#A.~.G#\n#..~..#\n#######\n"))
    # a closed door and no toggle action: the message says which is missing
    with pytest.raises(SpecError, match="there is no toggle action, so no closed door can be opened"):
        bfs.check_reachable(_user_task(tmp_path, "########\n#A.yYG.#\n########\n",
                                       actions="[left, right, forward, pickup, drop]"))


def test_a_maze_that_needs_one_key_swapped_for_another_object_is_checked_by_putting_it_back(tmp_path):
    """Holding the yellow key, the agent must put it down to pick up the ball behind the door: the search
    without drop misses the ball, and the one that only puts objects back on their starting cells finds
    it within a cap that the whole search passes."""
    ball = "  - {name: ball, kind: carrying, args: {type: ball, color: green}}\n"
    path = _user_task(tmp_path, "#########\n#A.y#o..#\n#...Y..G#\n#########\n", extra_subgoals=ball)
    kept = ["left", "right", "forward", "pickup", "toggle", "done"]
    no_drop, put_back, whole = _states(path, kept), _states(path, put_back=True), _states(path)
    assert no_drop < put_back < whole // 5
    spec = load_maze_spec(path)
    swap = bfs._bfs(spec, spec.initial_state(0), lambda s: bfs.holds(spec, s, 1), put_back=True)
    names = [spec.options.actions[a] for a in swap]
    assert names.count("drop") == 1 and names.count("pickup") == 2    # key up, key back, ball up
    assert bfs.check_reachable(path, max_states=no_drop + put_back + 10) == []
    assert bfs.check_reachable(path, max_states=put_back // 2) is None
    # a maze nothing can be dropped in: the ball stays out of reach, and the whole search says so
    assert bfs.check_reachable(_user_task(tmp_path, "#########\n#A.y#o..#\n#...Y..G#\n#########\n",
                                          actions="[left, right, forward, pickup, toggle]",
                                          extra_subgoals=ball)) == ["ball"]


@pytest.mark.parametrize("task", ["keydoor", "fourroom", "threepair", "detour", "vault_moved", "keydoor_incorrect",
                                  "annex_wide", "gallery", "gallery_turned", "moat", "moat_mirror",
                                  "chain"])
def test_every_subgoal_of_the_shipped_mazes_is_reachable(task):
    assert bfs.check_reachable(task) == []
    assert bfs.check_reachable(task, max_states=1) is None     # the relaxation alone finds nothing wrong


def _forge(tmp_path, name, layout, bridge):
    """A 15x11 maze with drop and three carriable objects: a start room, a middle room and a goal room,
    entered by the purple key and door or by the lava bridge (sub-goal ``bridge`` at that cell) and the
    grey door; the red key opens the red door to the goal; a yellow ball opens nothing."""
    (tmp_path / f"{name}.txt").write_text(textwrap.dedent(layout).lstrip())
    path = tmp_path / f"{name}.yaml"
    path.write_text(textwrap.dedent(f"""\
        task: {name}
        family: minigrid
        options:
          layout: {name}.txt
          legend:
            p: {{type: key, color: purple}}
            P: {{type: door, color: purple, locked: true}}
            r: {{type: key, color: red}}
            R: {{type: door, color: red, locked: true}}
            E: {{type: door, color: grey}}
            o: {{type: ball, color: yellow}}
          max_steps: 800
          start_dir: right
          actions: [left, right, forward, pickup, drop, toggle]
        subgoals:
          - {{name: purple_key, kind: carrying, args: {{type: key, color: purple}}}}
          - {{name: purple_door, kind: door_open, args: {{color: purple}}}}
          - {{name: bridge, kind: at, args: {{cell: {list(bridge)}}}}}
          - {{name: grey_door, kind: door_open, args: {{color: grey}}}}
          - {{name: red_key, kind: carrying, args: {{type: key, color: red}}}}
          - {{name: red_door, kind: door_open, args: {{color: red}}}}
          - {{name: ball, kind: carrying, args: {{type: ball, color: yellow}}}}
          - {{name: goal, kind: goal}}
        """))
    return path


def _passes_cap(path, max_states):
    """Whether the whole search from the start visits more than ``max_states`` states."""
    spec = load_maze_spec(path)
    try:
        bfs._bfs(spec, spec.initial_state(0), lambda s: False, max_states=max_states)
    except RuntimeError:
        return True
    return False


DEFAULT_CAP = inspect.signature(bfs.check_reachable).parameters["max_states"].default


def test_a_maze_too_large_to_search_whose_goal_is_behind_its_own_key_is_refused(tmp_path):
    """The red key lies behind the red door: the whole search passes the cap, and the relaxation (keys
    and doors over cells) shows that the goal cannot be reached."""
    path = _forge(tmp_path, "unreach", """
        ###############
        #A....#...#...#
        #.....#...#...#
        #..p..P...R.G.#
        #.....#...#...#
        #..o..#...#...#
        #.....#...#.r.#
        #~~.~~#...#...#
        #.....E...#...#
        #.....#...#...#
        ###############
        """, (3, 7))
    assert _passes_cap(path, DEFAULT_CAP)
    with pytest.raises(SpecError, match=r"the goal \(12, 3\) cannot be reached from the start \(1, 1\)"):
        bfs.check_reachable(path)
    with pytest.raises(SpecError, match="cannot be reached"):
        bfs.check_reachable(path, max_states=1)


def test_a_walled_in_ball_in_a_maze_too_large_to_search_is_named(tmp_path):
    path = _forge(tmp_path, "walled", """
        ###############
        #A..#o#...#...#
        #....##...#...#
        #..p..P...R.G.#
        #.....#...#...#
        #.....#.r.#...#
        #.....#...#...#
        #~~.~~#...#...#
        #.....E...#...#
        #.....#...#...#
        ###############
        """, (3, 7))
    assert _passes_cap(path, DEFAULT_CAP)
    assert bfs.check_reachable(path) == ["ball"]
    assert bfs.check_reachable(path, max_states=1) == ["ball"]     # the relaxation alone


_MOVED = """
    ###############
    #.....#...#...#
    #..o..E...#.G.#
    #.....#...#...#
    #~.~~~#...R...#
    #.....#.r.#...#
    #..A..#...#...#
    #.....P...#...#
    #.p...#...#...#
    #.....#...#...#
    ###############
    """


def test_a_subgoal_on_lava_is_never_achieved(tmp_path):
    """Stepping onto the lava puts the agent on the cell, but the episode has ended there: the sub-goal
    is of no use, so it counts as never achieved, in the exact search and in the relaxation."""
    path = _forge(tmp_path, "lava", _MOVED, (1, 4))
    spec = load_maze_spec(path)
    s = spec.initial_state(0)
    for a in bfs.plan(spec, "bridge"):          # the only way onto the cell ends the episode
        s = bfs.transition(spec, s, spec.options.actions[a])
    assert s.pos == (1, 4) and s.pos in spec.layout.lava
    assert bfs.check_reachable(path) == ["bridge"]
    assert bfs.check_reachable(path, max_states=1) == ["bridge"]
    # the gap in the lava is an ordinary cell
    assert bfs.check_reachable(_forge(tmp_path, "gap", _MOVED, (2, 4))) == []


def test_a_maze_too_large_to_search_with_everything_reachable_is_not_checked(tmp_path):
    path = _forge(tmp_path, "gap", _MOVED, (2, 4))
    assert _passes_cap(path, 2000)
    assert bfs.check_reachable(path, max_states=2000) is None
    assert bfs.check_reachable(path) == []


def test_the_relaxation_misses_nothing_that_a_state_reaches(tmp_path):
    """On random small mazes (open, closed and locked doors, keys and balls, lava, random action
    subsets) every sub-goal the whole search achieves, and the goal, are reachable in the relaxation."""
    rng = np.random.default_rng(7)
    legend = ("y: {type: key, color: yellow}\n    r: {type: key, color: red}\n    o: {type: ball, color: green}\n"
              "    Y: {type: door, color: yellow, locked: true}\n    R: {type: door, color: red, locked: true}\n"
              "    d: {type: door, color: blue}\n    e: {type: door, color: grey, open: true}")
    kinds = {"y": "carrying, args: {type: key, color: yellow}", "r": "carrying, args: {type: key, color: red}",
             "o": "carrying, args: {type: ball, color: green}", "Y": "door_open, args: {color: yellow}",
             "R": "door_open, args: {color: red}", "d": "door_open, args: {color: blue}",
             "e": "door_open, args: {color: grey}"}
    pruned = 0
    for k in range(60):
        w, h = int(rng.integers(4, 7)), int(rng.integers(3, 6))
        inner = [(x, y) for x in range(1, w - 1) for y in range(1, h - 1)]
        cells = [inner[i] for i in rng.permutation(len(inner))]
        grid = {c: str(rng.choice(list("....##~"))) for c in cells}
        grid[cells[0]], grid[cells[1]] = "A", "G"
        items = list(rng.permutation(list(kinds)))[:min(len(cells) - 2, int(rng.integers(0, 5)))]
        grid.update(zip(cells[2:], items))
        rows = ["".join(grid.get((x, y), "#") for x in range(w)) for y in range(h)]
        actions = ["left", "right"] + [a for a in ("forward", "pickup", "drop", "toggle") if rng.random() < 0.85]
        subgoals = [f"  - {{name: at_{x}_{y}, kind: at, args: {{cell: [{x}, {y}]}}}}" for x, y in inner
                    if grid[(x, y)] != "#"]
        subgoals += [f"  - {{name: has_{c}, kind: {kinds[c]}}}" for c in items]
        (tmp_path / f"m{k}.txt").write_text("\n".join(rows) + "\n")
        (tmp_path / f"m{k}.yaml").write_text(
            f"task: m{k}\nfamily: minigrid\noptions:\n  layout: m{k}.txt\n  legend:\n    {legend}\n"
            f"  actions: [{', '.join(actions)}]\nsubgoals:\n  - {{name: goal, kind: goal}}\n"
            + "\n".join(subgoals) + "\n")
        spec = load_maze_spec(tmp_path / f"m{k}.yaml")
        states = []
        bfs._bfs(spec, spec.initial_state(0), lambda s: states.append(s) or False, max_states=10**7)
        # from the start, and from a state part way (an object carried, doors opened) as an env may be in
        for start in (spec.initial_state(0), states[int(rng.integers(len(states)))]):
            achieved = set()

            def visit(s):
                if s.pos not in spec.layout.lava:
                    achieved.update(i for i in range(len(spec.predicates)) if bfs.holds(spec, s, i))
                return False

            bfs._bfs(spec, start, visit, max_states=10**7)
            goal, never = bfs._relaxed(spec, start)
            assert not never & achieved, (rows, actions, start)
            assert goal or 0 not in achieved, (rows, actions, start)
            pruned += len(never)
    assert pruned > 50    # and the relaxation does rule sub-goals out


def test_goal_beyond_max_steps_gives_zero_return(tmp_path):
    path = _user_task(tmp_path, "#######\n#A...G#\n#######\n", max_steps=3)
    assert bfs.optimal_steps(path) == 4
    assert bfs.optimal_return(path) == 0.0


def test_locked_door_needs_the_matching_key(tmp_path):
    # the red key does not open the yellow door; one must fetch the yellow key behind the agent
    path = _user_task(tmp_path, "#######\n#y.AYG#\n##r####\n#######\n",
                      actions="[left, right, forward, pickup, toggle]")
    actions = bfs.plan(path)
    names = [load_maze_spec(path).options.actions[a] for a in actions]
    assert names.count("pickup") == 1 and names.count("toggle") == 1
    # turn around (2), forward to (2,1), pickup y, turn around (2), forward to (3,1), toggle,
    # forward into door (4,1), forward to goal: 10
    assert len(actions) == 10


def test_transition_matches_minigrid_on_random_rollouts(tmp_path):
    """The BFS model and MiniGrid agree on every step of long random rollouts with all actions
    (drop and done included), several objects, a plain door and a locked one."""
    layout = "########\n#A.o.Y.#\n#.y.r.d#\n#..##.G#\n########\n"
    extra = ("  - {name: blue_open, kind: door_open, args: {cell: [6, 2]}}\n"
             "  - {name: yellow_open, kind: door_open, args: {color: yellow}}\n"
             "  - {name: has_red, kind: carrying, args: {type: key, color: red}}\n"
             "  - {name: has_ball, kind: carrying, args: {type: ball, color: green}}\n"
             "  - {name: corner, kind: at, args: {cell: [1, 3]}}\n")
    path = _user_task(tmp_path, layout, max_steps=400, extra_subgoals=extra)
    spec = load_maze_spec(path)
    env = make(path)
    rng = np.random.default_rng(123)
    changes = 0
    seen = np.zeros(6, dtype=bool)
    for episode in range(30):
        env.reset(seed=episode)
        s = env.unwrapped.symbolic_state()
        for _ in range(400):
            a = int(rng.integers(env.action_space.n))
            expected = bfs.transition(spec, s, spec.options.actions[a])
            _, _, terminated, truncated, info = env.step(a)
            s_env = env.unwrapped.symbolic_state()
            assert s_env == expected, (spec.options.actions[a], s, s_env)
            assert info["subgoals"].tolist() == [bfs.holds(spec, s_env, i) for i in range(6)]
            seen |= info["subgoals"]
            changes += (s_env.objects != s.objects) + (s_env.doors != s.doors)
            s = s_env
            if terminated or truncated:
                break
    assert changes > 20  # the rollouts really moved objects and opened doors
    assert seen[1:].all(), seen  # and every predicate held at some point


@pytest.mark.parametrize("task, steps", [("threepair", 12), ("threepair_moved", 18), ("twowall", 30),
                                         ("vault", 26), ("vault_moved", 33), ("keydoor_n9", 19),
                                         ("keydoor_n17", 19), ("keydoor_n33", 19), ("keydoor_n65", 19),
                                         ("detour", 20), ("annex", 14), ("annex_wide", 18),
                                         ("gallery", 19), ("gallery_turned", 27), ("moat", 15),
                                         ("moat_mirror", 15), ("chain", 21)])
def test_new_mazes_have_their_bfs_optimum(task, steps):
    assert optimal_steps(task) == steps


@pytest.mark.parametrize("task", ["keydoor_n17", "keydoor_n65"])
def test_distractor_cells_are_off_every_near_shortest_path(task):
    from hubsgo_ppl.envs import get_task
    from hubsgo_ppl.envs.minigrid.bfs import shortest_path_cells

    near = shortest_path_cells("keydoor", slack=2)
    cat = get_task(task).catalogue
    cells = [tuple(p.args["cell"]) for p in cat.subgoals if p.kind == "at"]
    assert len(cells) == len(cat.names) - 5 and len(set(cells)) == len(cells)
    assert not near & set(cells)


def test_shortest_path_cells_cover_both_keydoor_routes_and_grow_with_slack():
    from hubsgo_ppl.envs.minigrid.bfs import shortest_path_cells

    exact = shortest_path_cells("keydoor")
    assert {(1, 6), (4, 4), (8, 4), (4, 8), (8, 8), (11, 6)} <= exact     # start, both routes, goal
    assert (1, 1) not in exact and exact < shortest_path_cells("keydoor", slack=2)



CHAIN = """\
###########
#A.y#..r#.#
#...Y...R.#
#...#...#G#
###########
"""


def test_a_chain_of_keys_without_drop_names_the_missing_drop(tmp_path):
    path = _user_task(tmp_path, CHAIN, "[left, right, forward, pickup, toggle]")
    with pytest.raises(SpecError, match="cannot be reached") as err:
        bfs.check_reachable(path)
    assert "there is no drop action" in str(err.value) and "add drop to options.actions" in str(err.value)
    assert "key on the agent's side" not in str(err.value)
    assert bfs.check_reachable(_user_task(tmp_path, CHAIN, "[left, right, forward, pickup, drop, toggle]")) == []


def test_a_key_behind_its_own_door_keeps_the_key_hint(tmp_path):
    behind = CHAIN.replace("#A.y#..r#", "#A..#.yr#")        # the yellow key behind the yellow door
    path = _user_task(tmp_path, behind, "[left, right, forward, pickup, toggle]")
    with pytest.raises(SpecError, match="key on the agent's side"):
        bfs.check_reachable(path)


@pytest.mark.parametrize("start_dir", ["right", "random"])
def test_steps_range_with_a_room_start_covers_every_cell_of_the_room(tmp_path, start_dir):
    """With options.start: room the shortest solution depends on the cell drawn, not only the heading:
    the range is every room cell's (and each drawn heading's), as a search from each start finds it."""
    room = "#######\n#A...y#\n#.....#\n###Y###\n#....G#\n#######\n"
    path = _user_task(tmp_path, room, start_dir=start_dir)
    path.write_text(path.read_text().replace("  layout: u.txt", "  layout: u.txt\n  start: room"))
    spec = load_maze_spec(path)
    dirs = range(4) if start_dir == "random" else [0]
    each = [len(bfs._bfs(spec, spec.initial_state(d)._replace(pos=cell), lambda s: s.pos == spec.layout.goal))
            for cell in spec.layout.start_room() for d in dirs]
    assert bfs.optimal_steps_range(path) == (min(each), max(each))
    assert min(each) < bfs.optimal_steps(path, start_dir=0) < max(each)   # A is neither end of it
