"""Sub-goal catalogues: the shipped ones load, and bad ones are refused naming the file and key."""

import textwrap

import pytest

from hubsgo_ppl.envs.subgoals import Catalogue, SubgoalDef, load_catalogue
from hubsgo_ppl.resources import envs_dir
from hubsgo_ppl.specs import SpecError


def test_shipped_keydoor_catalogue():
    cat = load_catalogue(envs_dir() / "keydoor.yaml")
    assert cat.task == "keydoor" and cat.family == "minigrid"
    assert cat.names == ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]
    assert cat.resolve(cat.options["layout"]) == envs_dir() / "keydoor.txt"
    assert cat.source == str(envs_dir() / "keydoor.yaml")
    assert "source" not in cat.model_dump()                           # where it came from is not data
    assert load_catalogue(envs_dir() / "stack_cubes.yaml").family == "robosuite"


def _write(tmp_path, body):
    path = tmp_path / "task.yaml"
    path.write_text(textwrap.dedent(body))
    return path


@pytest.mark.parametrize("subgoals, fragment", [
    ("[]", "at least one sub-goal"),
    ("[{name: a, kind: goal}, {name: a, kind: goal}]", "duplicate sub-goal name 'a'"),
    ("[{name: 'a b', kind: goal}]", "must be letters, digits"),
    ("[{name: a}]", "kind"),
])
def test_bad_catalogues_name_the_file_and_the_problem(tmp_path, subgoals, fragment):
    path = _write(tmp_path, f"""
        task: t
        family: minigrid
        subgoals: {subgoals}
        """)
    with pytest.raises(SpecError, match=fragment) as err:
        load_catalogue(path)
    assert str(path) in str(err.value)


def test_family_is_checked_and_models_build_directly(tmp_path):
    with pytest.raises(SpecError, match="family"):
        load_catalogue(_write(tmp_path, "task: t\nfamily: atari\nsubgoals: [{name: a, kind: goal}]\n"))
    cat = Catalogue(task="t", family="robosuite", subgoals=[SubgoalDef(name="lift-1", kind="grasp", args={"obj": 0})])
    assert cat.names == ["lift-1"] and cat.subgoals[0].args == {"obj": 0}


@pytest.mark.parametrize("head, fragment", [
    ("task: my maze", "task name 'my maze' must be letters, digits, '_' or '-'"),
    ("task: t\ntitle: Moat, mirrored", "title 'Moat, mirrored' names the Gymnasium id hubsgo/TITLE-v0, so it must be "
                                       "letters, digits, '_', '-' or '.'; e.g. 'MoatMirrored'"),
])
def test_a_task_name_or_title_that_cannot_name_a_gymnasium_id_is_refused(tmp_path, head, fragment):
    path = _write(tmp_path, head + "\nfamily: minigrid\nsubgoals: [{name: a, kind: goal}]\n")
    with pytest.raises(SpecError, match=fragment) as err:
        load_catalogue(path)
    assert str(path) in str(err.value)


def test_every_shipped_title_makes_a_gymnasium_id_that_gymnasium_parses():
    from gymnasium.envs.registration import parse_env_id

    from hubsgo_ppl.envs import tasks

    for name, info in tasks().items():
        namespace, env_name, version = parse_env_id(info.env_id)
        assert namespace == "hubsgo" and version == 0 and env_name, name
