"""The sub-goal contract checker (hubsgo_ppl/envs/check.py, `hubsgo check-env`)."""

import gymnasium as gym
import numpy as np
import pytest
import yaml

from hubsgo_ppl.cli import main
from hubsgo_ppl.envs import make, tasks
from hubsgo_ppl.envs.check import check_env, env_notes


class Corridor(gym.Env):
    """A 1-D corridor with two switches; ``broken`` names the part of the contract it breaks."""

    subgoal_names = ["switch_a", "goal"]

    def __init__(self, broken: str = ""):
        self.broken = broken
        dtype = np.float64 if broken == "dtype" else np.float32
        self.observation_space = gym.spaces.Box(0.0, 10.0, (1,), dtype)
        self.action_space = gym.spaces.Discrete(2)
        self.pos = 0

    def _obs(self):
        return np.array([self.pos], dtype=self.observation_space.dtype)

    def _info(self):
        flags = np.array([self.pos >= 3, self.pos >= 6], dtype=bool)
        if self.broken == "length":
            flags = flags[:1]
        info = {"subgoals": flags, "is_success": bool(self.pos >= 6)}
        if self.broken == "success":
            info.pop("is_success")
        return info

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        # the broken version draws from numpy's global generator, which reset(seed) does not set
        self.pos = int(np.random.randint(3)) if self.broken == "global_rng" else int(self.np_random.integers(3))
        return self._obs(), self._info()

    def step(self, action):
        self.pos = min(max(self.pos + (1 if action == 1 else -1), 0), 6)
        return self._obs(), float(self.pos >= 6), self.pos >= 6, False, self._info()


def test_every_shipped_maze_meets_the_contract():
    mazes = [name for name, info in tasks().items() if info.family == "minigrid" and "layout" in info.catalogue.options]
    assert len(mazes) >= 20
    for name in mazes:
        env = make(name)
        assert check_env(env, steps=30) == [], name
        assert env_notes(env) == [], name       # shaping and the scripted low level both work on a maze


@pytest.mark.mujoco
def test_an_arm_task_meets_the_contract_with_no_note():
    """Its low levels (scripted or learned) reach subgoal_target; the grid low level's shaping
    (subgoal_potential) does not apply to a continuous action space, so it is not noted as missing."""
    env = make("push_any_one")
    try:
        assert check_env(env, steps=10) == []
        assert env_notes(env) == []
    finally:
        env.close()


def test_a_corridor_that_meets_the_contract_passes():
    assert check_env(Corridor()) == []


@pytest.mark.parametrize("broken, what", [
    ("dtype", ["observation_space"]),
    ("length", ['info["subgoals"] after reset', 'info["subgoals"] after step']),
    ("success", ['info["is_success"] after reset', 'info["is_success"] after step']),
    ("global_rng", ["reset(seed=...)"]),
])
def test_each_broken_part_is_named_once_and_nothing_else(broken, what):
    np.random.seed(0)       # the broken reset reads the global generator; two rollouts must still differ
    problems = check_env(Corridor(broken), steps=20)
    assert [p.what for p in problems] == what


def test_a_plain_gymnasium_env_lacks_the_names_and_both_info_keys():
    problems = check_env(gym.make("CartPole-v1"), steps=5)
    assert [p.what for p in problems] == ["unwrapped.subgoal_names", 'info["subgoals"] after reset',
                                          'info["is_success"] after reset', 'info["subgoals"] after step',
                                          'info["is_success"] after step']
    assert all(p.fix and "\n" not in str(p) for p in problems)


def test_the_cli_passes_a_task_fails_a_plain_env_and_refuses_an_unknown_one(capsys):
    assert main(["check-env", "keydoor", "--steps", "20"]) == 0
    assert "meets the sub-goal contract" in capsys.readouterr().out
    assert main(["check-env", "CartPole-v1", "--steps", "5"]) == 1
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 6 and all(line.startswith("missing: ") for line in out[:5])
    # a plain id is pointed at the catalogue that trains it as it is, not at writing the contract by hand
    assert out[5].startswith("note: to train on it as it is, write a catalogue with family: gym")
    assert main(["check-env", "Pendulum-v1", "--steps", "5"]) == 1
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("note: its actions are Box") and "Discrete actions only" in last
    assert main(["check-env", "no_such_env"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown task 'no_such_env'" in err[0]


def test_a_minigrid_id_is_checked_and_pointed_to_the_catalogue_route_with_a_draft(capsys, tmp_path):
    assert main(["check-env", "MiniGrid-Unlock-v0", "--steps", "10"]) == 1
    out = capsys.readouterr().out.strip().split("\n\n")
    lines = out[0].splitlines()
    missing = [line for line in lines if line.startswith("missing: ")]
    assert missing[0].startswith("missing: observation_space: a flat gymnasium.spaces.Box is needed, got Dict")
    assert any("unwrapped.subgoal_names" in line for line in missing)
    assert lines[-1].startswith("note: a MiniGrid environment") and "options.gym_id" in lines[-1]
    assert "docs/minigrid.md" in lines[-1] and "save as unlock.yaml" in lines[-1]
    # the draft: Unlock's one locked door, the key that opens it, and the toggle on which Unlock pays
    draft = yaml.safe_load(out[1])
    assert draft == {"task": "unlock", "family": "minigrid",
                     "options": {"gym_id": "MiniGrid-Unlock-v0", "actions": ["left", "right", "forward", "pickup",
                                                                            "toggle"]},
                     "subgoals": [{"name": "key", "kind": "carrying", "args": {"type": "key"}},
                                  {"name": "locked_door", "kind": "door_open", "args": {"locked": True}},
                                  {"name": "goal", "kind": "goal"}]}
    path = tmp_path / "unlock.yaml"
    path.write_text(out[1])
    assert main(["check-env", str(path), "--steps", "10"]) == 0


@pytest.mark.parametrize("gym_id, names, actions", [
    ("MiniGrid-KeyCorridorS3R1-v0", ["key", "ball", "locked_door", "door", "goal"],
     ["left", "right", "forward", "pickup", "drop", "toggle"]),
    ("MiniGrid-RedBlueDoors-6x6-v0", ["blue_door", "red_door", "goal"], ["left", "right", "forward", "toggle"]),
    ("MiniGrid-GoToDoor-5x5-v0", ["door", "goal"], ["left", "right", "forward", "toggle", "done"]),
    ("MiniGrid-Empty-5x5-v0", ["goal"], ["left", "right", "forward"]),
])
def test_a_draft_names_what_every_seeded_layout_has_and_the_actions_it_needs(gym_id, names, actions):
    from hubsgo_ppl.envs.minigrid.draft import draft_catalogue

    draft = draft_catalogue(gym_id)
    assert [s["name"] for s in draft["subgoals"]] == names
    assert draft["options"]["actions"] == actions


@pytest.mark.parametrize("env_id, close", [("Foo-v0", None), ("MiniGrid-Unlok-v0", "MiniGrid-Unlock-v0")])
def test_an_id_that_is_not_registered_says_so(capsys, env_id, close):
    assert main(["check-env", env_id]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"{env_id!r} is not a registered Gymnasium id" in err[0], err
    assert "is a Gymnasium id, not a task" not in err[0]
    assert (close in err[0]) if close else "close:" not in err[0]


@pytest.mark.parametrize("layout, said", [
    ("#####\n#A..#\n#####\n#..G#\n#####\n", "the goal (3, 3) cannot be reached"),
    ("#######\n#A....#\n#.#Y###\n#....G#\n#######\n", "no state the agent can reach achieves door"),
])
def test_a_drawn_maze_that_tasks_refuses_or_warns_of_is_not_passed_silently(capsys, tmp_path, layout, said):
    """check-env plays a maze whose goal no action sequence reaches (or whose sub-goal none achieves)
    without fault; it says what `hubsgo tasks` and `train` say of it, and exits 1."""
    (tmp_path / "m.txt").write_text(layout)
    cat = tmp_path / "m.yaml"
    cat.write_text("task: m\nfamily: minigrid\noptions:\n  layout: m.txt\n  legend: {Y: {type: door, color: yellow,"
                   " locked: true}}\nsubgoals:\n  - {name: door, kind: door_open, args: {color: yellow}}\n"
                   "  - {name: goal, kind: goal}\n")
    if "Y" not in layout:
        cat.write_text(cat.read_text().replace("  - {name: door, kind: door_open, args: {color: yellow}}\n", "")
                       .replace("  legend: {Y: {type: door, color: yellow, locked: true}}\n", ""))
    assert main(["check-env", str(cat), "--steps", "10"]) == 1
    out = capsys.readouterr().out
    assert said in out and "but see the reachability warning above" in out
