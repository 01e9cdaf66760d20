"""StackCubes: success needs the cubes stacked in the right order."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.mujoco


def test_stack_cubes_success_needs_the_right_order(arm_env, put, achieved):
    e = arm_env("stack_cubes")
    t = e.unwrapped.task
    pad = t.place_top("target")
    put(e, "red", pad + [0, 0, 0.02])
    put(e, "green", pad + [0, 0, 0.06])
    assert t._check_success() and t.reward() == 1.0
    got = achieved(e)
    assert got["place_red_on_target"] and got["place_green_on_red"] and not got["place_green_on_target"]
    put(e, "green", pad + [0.2, 0.1, 0.02])            # green off the stack
    assert not t._check_success() and achieved(e)["place_red_on_target"]
    put(e, "green", pad + [0, 0, 0.02])                 # wrong order: green below, red on top
    put(e, "red", pad + [0, 0, 0.06])
    got = achieved(e)
    assert not t._check_success() and t.reward() == 0.0
    assert got["place_green_on_target"] and got["place_red_on_green"] and not got["place_red_on_target"]


ARMS = Path(__file__).resolve().parents[3] / "examples" / "arms"


@pytest.fixture(scope="module")
def stack_three():
    """The three-cube, two-pad example of docs/arms.md: -> (catalogue path, spec path)."""
    return ARMS / "stack_three.yaml", ARMS / "stack_three-spec.yaml"


def test_a_catalogue_adds_a_cube_colour_and_a_pad(put, stack_three):
    """The user-written StackThree: three cubes in the catalogue's order on either of two pads, the
    pads in strips of their own."""
    from hubsgo_ppl.envs.robosuite import make_robosuite_task

    env = make_robosuite_task(str(stack_three[0]))
    try:
        env.reset(seed=3)
        t = env.unwrapped.task
        assert t.cubes == ("red", "green", "blue") and t.pads == ("pad_a", "pad_b")
        assert env.observation_space.shape == (9 + 3 * 7 + 2 * 3 + 3 * 3,)
        a, b = (t.place_top(p) for p in t.pads)
        assert -0.11 - 1e-9 <= a[1] <= -0.05 + 1e-9 and 0.05 - 1e-9 <= b[1] <= 0.11 + 1e-9
        for pad in (a, b):
            put(env, "red", pad + [0, 0, 0.02])
            put(env, "green", pad + [0, 0, 0.06])
            put(env, "blue", pad + [0.25, 0.0, 0.02])
            assert not t._check_success()                       # two of three
            put(env, "blue", pad + [0, 0, 0.10])
            assert t._check_success() and t.reward() == 1.0     # on pad_a, then on pad_b
        put(env, "blue", b + [0, 0, 0.02])                      # wrong order: blue at the bottom
        put(env, "red", b + [0, 0, 0.06])
        put(env, "green", b + [0, 0, 0.10])
        assert not t._check_success()
    finally:
        env.close()


def test_a_three_cube_stack_is_three_place_options(stack_three):
    """The scripted low level builds the user-written three-cube stack with three place options, the
    third cube lowered onto the two-cube stack without knocking it down."""
    from hubsgo_ppl.agents.scripted_osc import ScriptedOSC
    from hubsgo_ppl.envs.robosuite import make_robosuite_task

    env = make_robosuite_task(str(stack_three[0]))
    try:
        env.reset(seed=0)
        names, ctrl = env.unwrapped.subgoal_names, ScriptedOSC()
        for goal in ("place_red_on_pad_b", "place_green_on_red", "place_blue_on_green"):
            i = names.index(goal)
            for _ in range(120):
                *_, info = env.step(ctrl.act(env, i))
                if info["subgoals"][i]:
                    break
            assert info["subgoals"][i], goal
        assert info["is_success"]
    finally:
        env.close()


@pytest.mark.parametrize("option, value, message", [
    ("cubes", "[red, pink]", r"options.cubes: \['red', 'pink'\] is not 1 to 4 distinct colours"),
    ("cubes", "[red, red]", r"options.cubes: \['red', 'red'\] is not 1 to 4 distinct colours"),
    ("pads", "[pad_a, pad_a]", r"options.pads: \['pad_a', 'pad_a'\] is not 1 to 3 distinct names"),
    ("pads", "[red]", r"options.pads: \['red'\] is not 1 to 3 distinct names"),
    ("pads", "[a, b, c, d]", r"options.pads: \['a', 'b', 'c', 'd'\] is not 1 to 3"),
])
def test_bad_stack_options_name_the_problem(tmp_path, stack_three, option, value, message):
    from hubsgo_ppl.envs.robosuite import make_robosuite_task
    from hubsgo_ppl.specs import SpecError

    text = stack_three[0].read_text()
    line = next(x for x in text.splitlines() if x.strip().startswith(f"{option}:"))
    bad = tmp_path / "bad.yaml"
    bad.write_text(text.replace(line, f"  {option}: {value}"))
    with pytest.raises(SpecError, match=message):
        make_robosuite_task(str(bad))


def test_the_worked_example_of_docs_arms_is_shipped_as_shown_and_passes_hubsgo_tasks(capsys):
    from hubsgo_ppl.cli import main

    paths = ARMS / "stack_two_pads.yaml", ARMS / "stack_two_pads-spec.yaml"
    page = (ARMS.parents[1] / "docs" / "arms.md").read_text(encoding="utf-8")
    assert re.findall(r"^```yaml\n(.*?)^```", page, flags=re.S | re.M)[:2] == [p.read_text() for p in paths]
    assert main(["tasks", str(paths[0]), "--model", str(paths[1])]) == 0
    assert "critic spec 'stack_two_pads-spec': 9 sub-goals, 10 edges" in capsys.readouterr().out


def test_an_arm_spec_that_leaves_out_the_likelihood_reads_the_successes_at_full_weight(tmp_path):
    """The robosuite family's likelihood (power 1, as every shipped arm spec states) for a user's spec
    without one and for --graph independent; a stated likelihood is kept, and a maze keeps power 0.25."""
    from hubsgo_ppl.experiments.resolve import resolve
    from hubsgo_ppl.experiments.run import RunConfig
    from hubsgo_ppl.infer.likelihoods import get_likelihood

    def power(task, **kw):
        lik = dict(resolve(RunConfig(task=str(task), agent="hubsgo", **kw))["model_spec"]["likelihood"])
        return get_likelihood(lik.pop("name"), **lik).power

    catalogue, spec = ARMS / "stack_two_pads.yaml", ARMS / "stack_two_pads-spec.yaml"
    assert "likelihood" not in spec.read_text()
    assert power(catalogue, model=str(spec)) == 1.0
    assert power(catalogue, graph="independent") == 1.0
    from hubsgo_ppl.experiments.revise import load_revision_spec     # a revision's spec: the same
    run = {"task": "stack_two_pads", "task_ref": str(catalogue), "family": "robosuite"}
    assert load_revision_spec(spec, run).likelihood.params() == {"flip": 0.02, "power": 1.0}
    stated = tmp_path / "stated.yaml"
    stated.write_text(spec.read_text() + "likelihood: {name: outcome, flip: 0.02, power: 0.5}\n")
    assert power(catalogue, model=str(stated)) == 0.5
    assert power("keydoor", graph="independent") == 0.25
    maze = tmp_path / "maze.yaml"           # the same spec file shape on a maze: the maze default
    shipped = yaml.safe_load((ARMS.parents[1] / "models" / "keydoor-specific.yaml").read_text())
    maze.write_text(yaml.safe_dump({k: shipped[k] for k in ("name", "subgoals", "edges")}))
    assert power("keydoor", model=str(maze)) == 0.25


def test_where_cubes_rest_is_lasting_where_the_hand_is_what_it_holds_and_a_ball_in_a_bin_are_not(arm_env):
    """``subgoal_lasting``: a success counts a placement or a push only where it still holds at its end;
    a reach or a grasp wherever it held on the way, and a ball in a bin (no option takes it out) too."""
    kinds = {"place_on": True, "push_to": True, "collect": False, "reach_above": False, "grasp": False}
    for task in ("stack_cubes", "push_any_one", "collect_three_balls"):
        env = arm_env(task).unwrapped
        got = dict(zip(env.subgoal_names, env.subgoal_lasting()))
        assert got == {sg.name: kinds[sg.kind] for sg in env.task._subgoals}, task
