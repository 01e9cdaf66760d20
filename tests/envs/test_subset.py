"""A task restricted to some of its catalogue's sub-goals: the env sees only those, in catalogue order;
the task itself (layout, observations, rewards) is unchanged; names outside the catalogue are refused."""

import numpy as np
import pytest

from hubsgo_ppl.envs import get_task, make, register
from hubsgo_ppl.envs.subset import catalogue_order, check_subset, make_subset, subset_catalogue
from hubsgo_ppl.specs import SpecError

INCORRECT = "keydoor_incorrect"


@pytest.fixture(autouse=True)
def _registered():
    register()


def test_subset_env_sees_only_the_listed_subgoals_in_catalogue_order():
    full = make(INCORRECT)
    names = ["goal", "yellow_door", "yellow_key"]                     # any order in, catalogue order out
    sub = make_subset(INCORRECT, names)
    assert sub.unwrapped.subgoal_names == ["yellow_key", "yellow_door", "goal"]
    a, info_a = full.reset(seed=5)
    b, info_b = sub.reset(seed=5)
    np.testing.assert_array_equal(a, b)                                # the task itself is unchanged
    idx = [full.unwrapped.subgoal_names.index(n) for n in sub.unwrapped.subgoal_names]
    assert info_b["subgoals"].tolist() == info_a["subgoals"][idx].tolist()
    for action in [1, 2, 2, 0, 2, 2, 3]:                               # same actions, same outcomes
        a, ra, ta, tra, info_a = full.step(action)
        b, rb, tb, trb, info_b = sub.step(action)
        np.testing.assert_array_equal(a, b)
        assert (ra, ta, tra) == (rb, tb, trb)
        assert info_b["subgoals"].tolist() == info_a["subgoals"][idx].tolist()
        assert sub.unwrapped.subgoal_achieved().tolist() == full.unwrapped.subgoal_achieved()[idx].tolist()
    for i, j in enumerate(idx):
        assert sub.unwrapped.subgoal_target(i) == full.unwrapped.subgoal_target(j)
    full.close()
    sub.close()


def test_all_or_none_of_the_subgoals_is_the_plain_task():
    cat = get_task("keydoor").catalogue
    assert subset_catalogue(cat, cat.names) is cat
    env = make_subset("keydoor", None, seed=3)
    assert env.unwrapped.subgoal_names == cat.names
    env.close()
    sub = subset_catalogue(cat, ["goal", "blue_key"])
    assert sub.names == ["blue_key", "goal"] and sub.source == cat.source and cat.names[0] == "yellow_key"


def test_names_outside_the_catalogue_are_refused_in_one_line():
    catalogue = ["a", "b", "c"]
    assert catalogue_order(["c", "a"], catalogue) == ["a", "c"]
    check_subset(["b"], catalogue, "spec.yaml")
    for names, message in [([], "none listed; list some of the task's sub-goals: a, b, c"),
                           (["a", "x"], "sub-goal 'x' is not in the task's catalogue, which can evaluate only: a, b, c"),
                           (["x", "y"], "sub-goals 'x', 'y' are not in the task's catalogue"),
                           (["a", "b", "a"], "a listed twice")]:
        with pytest.raises(SpecError, match=message) as err:
            check_subset(names, catalogue, "spec.yaml")
        assert str(err.value).startswith("spec.yaml: ") and "\n" not in str(err.value)
    with pytest.raises(SpecError, match="'door' is not in the task's catalogue"):
        make_subset("keydoor", ["door"])
