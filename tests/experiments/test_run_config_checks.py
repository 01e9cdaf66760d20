"""A RunConfig given from Python is refused in one line (a RunError), as the command line refuses its flags."""

import pytest

from hubsgo_ppl.experiments import RunConfig, RunError, train
from hubsgo_ppl.experiments.resolve import resolve_run


def test_an_unknown_agent_is_refused_before_anything_is_built():
    with pytest.raises(RunError, match="unknown agent 'hubsg'; use one of: .*hubsgo"):
        resolve_run(RunConfig(task="keydoor", agent="hubsg", steps=100))


@pytest.mark.parametrize("threads", [0, -1, "x", 1.5])
def test_threads_are_checked_before_torch_reads_them(tmp_path, threads):
    with pytest.raises(RunError, match="threads must be a positive whole number"):
        train(RunConfig(task="keydoor", steps=100, threads=threads), tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("change, what", [(dict(transfer=["critic"]), "transfer"),
                                          (dict(restart_schedules=True), "restart_schedules")])
def test_transfer_settings_without_a_source_run_are_refused(change, what):
    with pytest.raises(RunError, match=f"{what} .* from the run given by init_from"):
        resolve_run(RunConfig(task="keydoor", steps=100, **change))


@pytest.mark.parametrize("change, says", [(dict(task=None), "task must be a task name or the path of a catalogue"),
                                          (dict(task=3), "task must be a task name"),
                                          (dict(overrides="loop.option_steps=30"), "overrides must be a list of"),
                                          (dict(overrides=[("loop", 30)]), "overrides must be a list of")])
def test_a_task_or_overrides_of_the_wrong_type_is_one_line(tmp_path, change, says):
    with pytest.raises(RunError, match=says):
        train(RunConfig(**{"task": "keydoor", "steps": 100, **change}), tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("task, agent, actions, family",
                         [("keydoor", "td3", "continuous", "minigrid"),
                          ("push_any_one", "dqn", "discrete", "robosuite"),
                          ("push_any_one", "ddqn", "discrete", "robosuite")])
def test_a_flat_baseline_of_the_other_action_kind_is_refused_before_the_env_is_built(tmp_path, monkeypatch, task,
                                                                                   agent, actions, family):
    import hubsgo_ppl.experiments.restore as restore

    monkeypatch.setattr(restore, "make_subset", lambda *a, **k: pytest.fail("the env was built"))
    with pytest.raises(RunError, match=f"agent '{agent}' takes {actions} actions and does not train on {family} "
                                       "tasks; use one of: .*ppo"):
        train(RunConfig(task=task, agent=agent, steps=100), tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_the_scripted_maze_low_level_on_a_registered_minigrid_env_is_refused_before_anything_is_written(tmp_path):
    with pytest.raises(RunError, match="--low-level scripted plans on a maze's ASCII layout, and task 'doorkey_8x8' "
                                       "is the registered MiniGrid environment MiniGrid-DoorKey-8x8-v0"):
        train(RunConfig(task="doorkey_8x8", agent="hdqn", low_level="scripted", steps=100), tmp_path / "run",
              progress=False)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("agent", ["ppo", "hiro", "higl", "ddqn"])
def test_a_critic_spec_for_an_agent_without_sub_goals_is_refused_as_a_graph_is(tmp_path, agent):
    with pytest.raises(RunError, match=f"--model keydoor-specific sets the critic spec .* agent '{agent}' chooses "
                                       "from no sub-goal catalogue"):
        train(RunConfig(task="keydoor", agent=agent, model="keydoor-specific", steps=100), tmp_path / "run",
              progress=False)
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("change, given", [(dict(agent="ppo", low_level="learned"), "--low-level learned"),
                                           (dict(agent="hiro", low_level="scripted"), "--low-level scripted"),
                                           (dict(agent="td3", overrides=["low_level=learned"]),
                                            "--set low_level=learned")])
def test_a_low_level_for_an_agent_without_the_hrl_loop_is_refused(tmp_path, change, given):
    # on an arm task it changed only the budget (the learned low level's) of an agent that has no such choice
    with pytest.raises(RunError, match=f"^{given} picks the low level of hubsgo and hdqn, and agent"):
        train(RunConfig(task="push_any_one", steps=None if "overrides" in change else 100, **change),
              tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()
