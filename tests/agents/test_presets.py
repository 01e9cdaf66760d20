"""Hyperparameter presets: family defaults, per-task settings merged over them, and --set overrides."""

import pytest

from hubsgo_ppl.agents.presets import PRESETS, TASK_PRESETS, apply_overrides, preset


def test_task_settings_merge_over_the_family_defaults():
    cfg = preset("robosuite", "stack_cubes")
    assert cfg["steps"] == 20_000 and cfg["env"] == {"horizon": 400}
    assert cfg["loop"] == PRESETS["robosuite"]["loop"]      # the family's options and schedules, unchanged
    assert preset("robosuite", "push_any_one")["steps"] == 8_000
    assert preset("minigrid", "keydoor") == PRESETS["minigrid"]              # mazes have no own settings
    assert set(TASK_PRESETS) == {"stack_cubes", "push_any_one", "collect_three_balls"}
    with pytest.raises(KeyError, match="no hyperparameter preset for task family 'atari'"):
        preset("atari")


def test_presets_are_copies():
    cfg = preset("minigrid")
    cfg["high"]["hidden"].append(7)
    cfg["loop"]["option_steps"] = 99
    assert PRESETS["minigrid"]["high"]["hidden"] == [128, 128] and PRESETS["minigrid"]["loop"]["option_steps"] == 10


def test_overrides_parse_yaml_values_at_any_depth_and_leave_the_input_alone():
    base = preset("minigrid")
    cfg = apply_overrides(base, ["loop.option_steps=30", "high.hidden=[32, 16]", "dqn.policy_kwargs.net_arch=[8]",
                                 "high.lr=0.003", "loop.filter_given_achieved=false", "steps=500"])
    assert cfg["loop"]["option_steps"] == 30 and cfg["high"]["hidden"] == [32, 16]
    assert cfg["dqn"]["policy_kwargs"]["net_arch"] == [8] and cfg["high"]["lr"] == 0.003
    assert cfg["loop"]["filter_given_achieved"] is False and cfg["steps"] == 500
    assert base == PRESETS["minigrid"]


@pytest.mark.parametrize("item, message", [("loop.option_steps", "expected KEY=VALUE"),
                                           ("nope.x=1", "unknown section 'nope'"),
                                           ("steps.x=1", "unknown section 'steps'"),
                                           ("critic.lr=0.1",
                                            "^--set critic.lr=0.1: unknown section 'critic'; sections: dqn, env, high"),
                                           ("high.foo.x=1", "unknown section 'high.foo'; sections of high: none$")])
def test_bad_overrides_name_the_problem(item, message):
    with pytest.raises(ValueError, match=message):
        apply_overrides(preset("minigrid"), [item])


@pytest.mark.mujoco
def test_a_users_arm_task_trains_for_the_familys_episodes_at_its_horizon(tmp_path, capsys):
    """A robosuite catalogue with no budget of its own gets 100 episodes of its horizon (the catalogue's,
    ``--set env.horizon``'s, else the scenes' 500); the shipped tasks keep theirs, and a budget given with
    ``--steps`` or ``--set steps`` wins."""
    from hubsgo_ppl.experiments.resolve import resolve
    from hubsgo_ppl.experiments.resolved import RunConfig

    def catalogue(name, horizon):
        path = tmp_path / f"{name}.yaml"
        path.write_text(f"task: {name}\nfamily: robosuite\noptions:\n  env_class: StackCubes\n  cubes: [blue]\n"
                        + (f"  horizon: {horizon}\n" if horizon else "")
                        + "subgoals:\n  - {name: grasp_blue, kind: grasp, args: {object: blue}}\n")
        return str(path)

    def budget(task, **kw):
        return resolve(RunConfig(task=task, graph="independent", **kw))["hyper"]["steps"]

    short, unset = catalogue("short", 150), catalogue("unset", None)
    assert budget(short) == 15_000 and budget(short, low_level="learned") == 15_000
    assert "no --steps: 15,000 env steps, the robosuite family's 100 episodes of the task's 150-step horizon" in (
        capsys.readouterr().err)
    assert budget(unset) == 50_000
    assert budget(short, overrides=["env.horizon=80"]) == 8_000
    capsys.readouterr()
    assert budget(short, steps=1_234) == 1_234 and budget(short, overrides=["steps=999"]) == 999
    assert "no --steps" not in capsys.readouterr().err
    assert budget("stack_cubes") == 20_000 and budget("push_any_one") == 8_000
    assert budget("keydoor") == 40_000          # a maze family counts in env steps
    assert resolve(RunConfig(task=short, agent="hiro"))["hyper"]["steps"] == 15_000    # every agent alike


def test_the_shipped_arm_tasks_take_the_learned_low_levels_measured_budgets():
    """With the learned low level a shipped arm task trains for the budget its table was measured at; the
    scripted controller keeps the task's own, and ``--steps`` or ``--set steps`` wins over both."""
    from hubsgo_ppl.agents.config import resolve_hyper

    def budget(task, **kw):
        return resolve_hyper("robosuite", task, "hubsgo", **kw)["steps"]

    assert [budget(t, low_level="learned") for t in ("push_any_one", "stack_cubes", "collect_three_balls")] == [
        15_000, 25_000, 50_000]
    assert [budget(t) for t in ("push_any_one", "stack_cubes", "collect_three_balls")] == [8_000, 20_000, 12_000]
    assert budget("stack_cubes", low_level="scripted") == 20_000
    assert budget("stack_cubes", low_level="learned", steps=3_000) == 3_000
    assert budget("stack_cubes", low_level="learned", overrides=["steps=4000"]) == 4_000
    assert resolve_hyper("robosuite", "stack_cubes", "hdqn", low_level="learned")["steps"] == 25_000


@pytest.mark.mujoco
def test_a_users_catalogue_named_as_a_shipped_task_takes_the_familys_defaults_not_the_tasks(tmp_path):
    """The task settings belong to the shipped catalogue (by name or by its file's path); a user's own
    catalogue that reuses the name keeps its own horizon and trains for the family's episodes of it."""
    from hubsgo_ppl.envs import get_task
    from hubsgo_ppl.experiments.resolve import resolve
    from hubsgo_ppl.experiments.resolved import RunConfig

    own = tmp_path / "stack_cubes.yaml"
    own.write_text("task: stack_cubes\nfamily: robosuite\noptions:\n  env_class: StackCubes\n  cubes: [blue]\n"
                   "  horizon: 300\nsubgoals:\n  - {name: grasp_blue, kind: grasp, args: {object: blue}}\n")
    hyper = resolve(RunConfig(task=str(own), agent="hdqn"))["hyper"]
    assert hyper["steps"] == 30_000 and "horizon" not in hyper.get("env", {})
    assert resolve(RunConfig(task=str(own), agent="hdqn", low_level="learned"))["hyper"]["steps"] == 30_000
    shipped = get_task("stack_cubes")
    assert shipped.shipped and not get_task(str(own)).shipped
    by_path = resolve(RunConfig(task=str(shipped.catalogue_path)))["hyper"]
    assert by_path["steps"] == 20_000 and by_path["env"] == {"horizon": 400}
