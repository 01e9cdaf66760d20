import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from hubsgo_ppl.infer.critic import SubgoalCritic
from hubsgo_ppl.specs import ModelSpec, SpecError, list_model_specs, load_model_spec

BASE = {
    "name": "t",
    "subgoals": ["a", "b", "c"],
    "graph": "specific",
    "edges": [["a", "b", "positive"], ["b", "c", "negative"]],
    "prior": {"name": "bernoulli", "p": 0.5},
    "likelihood": {"name": "gaussian", "scale": 1.0},
    "inference": {"lr": 0.05, "burn_in": 32, "num_samples": 64, "kernel": "single_site", "baseline_beta": 0.9,
                  "init": "edges"},
}


def write(tmp_path, **changes):
    data = {**BASE, **changes}
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def test_valid_spec_builds_a_critic(tmp_path):
    spec = load_model_spec(write(tmp_path))
    assert isinstance(spec, ModelSpec) and spec.edges[1] == ("b", "c", "negative")
    critic = SubgoalCritic.from_spec(spec, seed=0)
    assert critic.factors()["pairwise"] == {("a", "b"): 1.0, ("b", "c"): -1.0}
    assert load_model_spec(write(tmp_path), graph="independent").graph == "independent"


@pytest.mark.parametrize(
    "changes, key, fix",
    [
        ({"sigma": 1.0}, "sigma", "unknown key; remove it"),
        ({"inference": {"lr": 0.1, "burnin": 3}}, "inference.burnin", "unknown key"),
        ({"edges": [["a", "z", "positive"]]}, "edges[0]", "'z' is not in subgoals; use one of: a, b, c"),
        ({"subgoals": ["a", "b", "key_red"], "edges": [["a", "key_rde", "positive"]]}, "edges[0]",
         "'key_rde' is not in subgoals; subgoals lists 'key_red': correct the spelling in whichever of the two is wrong"),
        ({"subgoals": ["a", "b", "a"], "edges": []}, "subgoals", "duplicate name 'a'"),
        ({"edges": [["a", "b", "positive"], ["b", "a", "negative"]]}, "edges[1]",
         "'b'-'a' is given both 'positive' and 'negative'; keep the sign you believe, or 'unknown'"),
        ({"edges": [["a", "b", "positive"], ["b", "a", "positive"]]}, "edges[1]", "duplicate edge 'b'-'a'"),
        ({"name": ""}, "name", "empty"),
        ({"likelihood": {"name": "gaussian", "scale": -1.0}}, "likelihood", "scale must be > 0"),
        ({"likelihood": {"name": "gaussian", "scale": 0}}, "likelihood", "scale must be > 0"),
        ({"subgoals": [], "edges": []}, "subgoals", "N = 0"),
        ({"prior": {"name": "dirichlet"}}, "prior", "registered: bernoulli, beta_bernoulli, ising"),
        ({"prior": {"name": "ising", "strength": -3.0}}, "prior", "strength must be >= 0"),
        # numbers float32 cannot hold, YAML's 1e308 (text) included, and a list where a number goes
        ({"prior": {"name": "ising", "strength": "1e308", "field": -2}}, "prior",
         "'ising': strength = '1e308' is out of range; give a number between 1e-09 and 1e+09 in size, or 0"),
        ({"prior": {"name": "ising", "strength": 3.0, "field": -1e39}}, "prior", "field = -1e+39 is out of range"),
        ({"likelihood": {"name": "gaussian", "scale": 1e-320}}, "likelihood", "scale = 1e-320 is out of range"),
        ({"prior": {"name": "ising", "strength": [1, 2]}}, "prior 'ising'",
         "give each parameter a number"),
        ({"inference": {"num_samples": 10**11}}, "inference.num_samples", "less than or equal to 65536"),
        ({"inference": {"lr": 1e300}}, "inference.lr", "less than or equal to 10"),
        ({"prior": {"name": "ising", "strength": "abc"}}, "prior 'ising' {'strength': 'abc'}",
         "could not convert string to float: 'abc'; give each parameter a number"),
        ({"prior": {"name": "ising", "strength": True}}, "prior", "'ising': strength takes a number, got True"),
        ({"likelihood": {"name": "cauchy"}}, "likelihood", "registered: gaussian, laplace, outcome, student_t"),
        ({"edges": [["a", "b", "strong"]]}, "edges[0][2]", "positive"),
        ({"graph": "dense"}, "graph", "fully_connected"),
        ({"inference": {"lr": -1.0}}, "inference.lr", "greater than 0"),
        ({"inference": {"kernel": "gibbs"}}, "inference.kernel", "'single_site' or 'block'"),
        ({"inference": {"jit": "yes"}}, "inference.jit", "valid boolean"),
    ],
)
def test_spec_errors_name_file_key_and_fix(tmp_path, changes, key, fix):
    path = write(tmp_path, **changes)
    with pytest.raises(SpecError) as err:
        load_model_spec(path)
    msg = str(err.value)
    assert str(path) in msg and key in msg and fix in msg, msg


def test_missing_spec_lists_builtins():
    with pytest.raises(SpecError, match="example-specific"):
        load_model_spec("no-such-spec")


def test_builtin_spec_loads_by_name_from_any_cwd(tmp_path):
    assert "example-specific" in list_model_specs()
    code = "from hubsgo_ppl.specs import load_model_spec; print(load_model_spec('example-specific').name)"
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(Path(__file__).resolve().parents[1])})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "example-specific"


def test_spec_subgoals_are_matched_to_the_catalogue_by_name_in_any_order():
    from hubsgo_ppl.specs import ModelSpec, SpecError, match_subgoals

    names = ["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"]
    spec = ModelSpec(name="s", subgoals=["goal", "blue_door", "yellow_key", "blue_key", "yellow_door"],
                     edges=[("yellow_key", "yellow_door", "positive"), ("blue_door", "goal", "positive")])
    matched = match_subgoals(spec, names, "my_spec.yaml")
    assert matched.subgoals == names and matched.edges == spec.edges
    assert match_subgoals(matched, names, "x") is matched
    short = ModelSpec(name="s", subgoals=["goal", "yellow_key", "yellow_door", "blue_dor"])
    with pytest.raises(SpecError) as err:
        match_subgoals(short, names, "my_spec.yaml")
    msg = str(err.value)
    assert msg.startswith("my_spec.yaml: subgoals: not in the task: blue_dor (it leaves out blue_key, blue_door); "
                          "a spec lists the task's sub-goals, all of them or some, in any order, and no others: "
                          "yellow_key, yellow_door, blue_key, blue_door, goal")
    assert "exactly" not in msg and "\n" not in msg


def test_a_name_the_catalogue_lacks_is_refused_with_the_subset_rule(tmp_path, capsys):
    """Every sub-goal of the task plus one it lacks: the line names the extra one and says what a spec may
    list (some or all of the task's sub-goals), not that it must list exactly the task's."""
    from hubsgo_ppl.cli import main

    spec = tmp_path / "extra.yaml"
    spec.write_text(yaml.safe_dump({"name": "extra", "subgoals": ["yellow_key", "yellow_door", "blue_key",
                                                                  "blue_door", "goal", "purple_key"]}))
    assert main(["tasks", "keydoor", "--model", str(spec)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "subgoals: not in the task: purple_key; a spec lists the task's sub-goals, all of them or some" in err[0]
    assert "exactly" not in err[0]


def test_a_spec_in_its_own_order_trains_on_the_catalogue_order(tmp_path):
    """The critic built from a reordered spec is the one built from the catalogue-ordered spec."""
    from hubsgo_ppl.experiments.run import RunConfig, resolve

    text = (Path(__file__).resolve().parents[1] / "models" / "keydoor-specific.yaml").read_text()
    text = text.replace("subgoals: [yellow_key, yellow_door, blue_key, blue_door, goal]",
                        "subgoals: [goal, blue_door, blue_key, yellow_door, yellow_key]")
    path = tmp_path / "mine.yaml"
    path.write_text(text)
    mine = resolve(RunConfig(task="keydoor", agent="hubsgo", model=str(path)))
    shipped = resolve(RunConfig(task="keydoor", agent="hubsgo"))
    assert mine["model_spec"]["subgoals"] == shipped["model_spec"]["subgoals"]
    assert mine["model_spec"]["edges"] == shipped["model_spec"]["edges"]


def test_a_spec_that_leaves_out_prior_likelihood_and_inference_gets_the_shipped_maze_critic(tmp_path):
    """Only sub-goals and edges: the same critic as keydoor-specific, which states every setting."""
    shipped = load_model_spec("keydoor-specific")
    data = {"name": shipped.name, "task": shipped.task, "subgoals": list(shipped.subgoals),
            "edges": [list(e) for e in shipped.edges]}
    path = tmp_path / "mine.yaml"
    path.write_text(yaml.safe_dump(data))
    assert load_model_spec(path).model_dump() == shipped.model_dump()
    # inference given without init: init still follows the prior
    data["inference"] = {"lr": 0.1}
    path.write_text(yaml.safe_dump(data))
    spec = load_model_spec(path)
    assert (spec.inference.init, spec.inference.lr) == ("prior", 0.1)
    # a prior the guide cannot start at: init falls back to the edges, and the critic builds
    data["prior"] = {"name": "beta_bernoulli", "alpha": 2.0, "beta": 2.0}
    path.write_text(yaml.safe_dump(data))
    spec = load_model_spec(path)
    assert spec.inference.init == "edges"
    # a stated init is kept
    data["inference"] = {"init": "edges"}
    data.pop("prior")
    path.write_text(yaml.safe_dump(data))
    assert load_model_spec(path).inference.init == "edges"


def test_init_prior_with_a_prior_the_guide_cannot_hold_is_refused_with_the_spec(tmp_path, capsys):
    """The spec is refused where it is validated, so `tasks --model` and `train` both say so in one line,
    before a critic is built; the same init with a prior the guide holds is valid."""
    from hubsgo_ppl.cli import main

    path = write(tmp_path, prior={"name": "beta_bernoulli", "alpha": 1.0, "beta": 1.0}, inference={"init": "prior"})
    with pytest.raises(SpecError, match=r"inference.init 'prior' needs a prior the guide .* 'beta_bernoulli' is "
                                        r"not one; use init: edges"):
        load_model_spec(path)
    assert load_model_spec(write(tmp_path, inference={"init": "prior"})).inference.init == "prior"
    spec = write(tmp_path, name="kd", subgoals=["yellow_key", "yellow_door", "blue_key", "blue_door", "goal"],
                 edges=[["yellow_key", "yellow_door", "positive"]],
                 prior={"name": "beta_bernoulli", "alpha": 1.0, "beta": 1.0}, inference={"init": "prior"})
    for argv in (["tasks", "keydoor", "--model", str(spec)],
                 ["train", "keydoor", "--model", str(spec), "--steps", "100", "--out", str(tmp_path / "run"),
                  "--no-progress"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "inference.init 'prior' needs" in err[0], err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("text, fix", [
    ("name: x\nsubgoals: [a, b\n", "not valid YAML (line 3, column 1: expected ',' or ']'"),
    ("name: x\nsubgoals: [a, b]\nprior: {name: ising}\nprior: {name: bernoulli}\n",
     "not valid YAML (line 4, column 1: duplicate key 'prior': give each key once)"),
])
def test_yaml_errors_name_the_line_and_a_key_given_twice_is_refused(tmp_path, text, fix):
    path = tmp_path / "spec.yaml"
    path.write_text(text)
    with pytest.raises(SpecError) as err:
        load_model_spec(path)
    assert str(err.value).startswith(f"{path}: {fix}"), str(err.value)


@pytest.mark.parametrize("text, says", [
    ("password: hunter2\nuser: rootpw\n", "not a critic spec: a critic spec is a YAML mapping with the keys name, "
                                          "task, subgoals, graph, edges, prior, likelihood, inference, and this "
                                          "file has none of them (models/keydoor-specific.yaml is an example)"),
    ("rootpw:x:0:0:rootpw:/rootpw:/bin/bash\nhunter2:x:1:1::/usr/sbin:/usr/sbin/nologin\n",
     "not a critic spec: a critic spec is a YAML mapping of keys, and this file holds text"),
    ("- hunter2\n- rootpw\n", "not a critic spec: a critic spec is a YAML mapping of keys, and this file holds a list"),
    ("hunter2: rootpw\nhunter2: again\n", "not valid YAML (line 2, column 1: duplicate key 'hunter2'"),
])
def test_a_file_that_is_not_a_spec_is_refused_in_one_line_without_its_content(tmp_path, text, says):
    path = tmp_path / "secrets.yaml"
    path.write_text(text)
    with pytest.raises(SpecError) as err:
        load_model_spec(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}: {says}") and "\n" not in msg, msg
    if "duplicate" not in says:                     # a YAML error names the key it stops at, nothing else
        assert not {"hunter2", "rootpw", "password", "bin"} & set(msg.replace(":", " ").replace(",", " ").split())


def test_the_unknown_keys_of_a_spec_are_named_shortened_in_one_line(tmp_path):
    long_keys = [f"key_{i}_" + "x" * 80 for i in range(9)]
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"name": "t", "subgoals": ["a", "b"], **{k: 1 for k in long_keys}}))
    with pytest.raises(SpecError) as err:
        load_model_spec(path)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"{path}: unknown keys key_0_xxx") and msg.count("key_") == 5
    assert msg.endswith("... and 4 more; remove them or check their spelling") and "x" * 40 not in msg, msg


def test_one_formatter_for_files_sub_keys_and_settings():
    """specs, the critic's settings and a maze's sub-goal arguments word pydantic's errors with one function."""
    import pydantic

    from hubsgo_ppl import specs, validation
    from hubsgo_ppl.infer.config import InferenceConfig, InferenceSpec

    assert specs.format_validation_error is validation.format_validation_error

    class Args(specs.StrictModel):
        cell: tuple[int, int]
        size: int = pydantic.Field(3, gt=0)

    with pytest.raises(pydantic.ValidationError) as err:
        Args.model_validate({"cell": [1, "y"], "colour": "red", "size": 0})
    fmt = specs.format_validation_error
    assert fmt("maze.yaml", err.value).splitlines() == [      # the signature every caller used keeps working
        "maze.yaml: cell[1]: Input should be a valid integer, unable to parse string as an integer",
        "maze.yaml: size: Input should be greater than 0",
        "maze.yaml: colour: unknown key; remove it or check its spelling"]
    assert fmt("maze.yaml", err.value, prefix="subgoals[2] (door).args", sep="; ", limit=2) == (
        "maze.yaml: subgoals[2] (door).args.cell[1]: Input should be a valid integer, unable to parse string as an "
        "integer; maze.yaml: subgoals[2] (door).args.size: Input should be greater than 0; maze.yaml: and 1 more "
        "problem")
    assert fmt("Args", err.value, model=Args, sep="; ").split("; ")[1:3] == [
        "Args.size = 0: input should be greater than 0 (default 3)", "Args.colour: unknown setting"]
    with pytest.raises(pydantic.ValidationError) as err:
        InferenceSpec(lr=-1.0, burn_in="x" * 500)
    with pytest.raises(ValueError) as mine:
        InferenceConfig(lr=-1.0, burn_in="x" * 500)
    assert str(mine.value) == fmt("InferenceConfig", err.value, model=InferenceConfig, sep="; ")
    assert str(mine.value).endswith(f"InferenceConfig.burn_in = '{'x' * 56}...: input should be a valid integer, "
                                    "unable to parse string as an integer (default 32)")


@pytest.mark.parametrize("given", ["folder", "folder/"])
def test_a_directory_given_as_the_spec_is_named_a_directory(tmp_path, capsys, given):
    from hubsgo_ppl.cli import main

    (tmp_path / "folder").mkdir()
    path = str(tmp_path / given)
    with pytest.raises(SpecError, match=r": a directory, not a spec file; pass the path of a critic spec's YAML"):
        load_model_spec(path)
    for argv in (["tasks", "keydoor", "--model", path],
                 ["train", "keydoor", "--model", path, "--out", str(tmp_path / "run"), "--no-progress"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "a directory, not a spec file" in err[0] and "no such" not in err[0], err


@pytest.mark.parametrize("options, subgoal, key", [
    ({"max_steps": True}, {"name": "g", "kind": "goal"}, "options.max_steps"),
    ({}, {"name": "c", "kind": "at", "args": {"cell": [True, 1]}}, "args.cell"),
])
def test_true_or_false_is_no_number_in_a_catalogue(tmp_path, options, subgoal, key):
    from hubsgo_ppl.envs import make

    (tmp_path / "m.txt").write_text("#####\n#A.G#\n#####\n")
    (tmp_path / "m.yaml").write_text(yaml.safe_dump({
        "task": "m", "family": "minigrid", "options": {"layout": "m.txt", **options},
        "subgoals": [subgoal, {"name": "goal", "kind": "goal"}]}))
    with pytest.raises(SpecError, match=rf"{key}: takes a number, not true or false"):
        make(tmp_path / "m.yaml")


def test_true_or_false_is_no_number_in_a_critic_spec(tmp_path):
    spec = {"name": "b", "subgoals": ["a", "goal"], "edges": [["a", "goal", "positive"]],
            "inference": {"burn_in": False, "num_samples": 64, "jit": True}}
    path = tmp_path / "b.yaml"
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(SpecError, match="inference.burn_in: takes a number, not true or false"):
        load_model_spec(str(path))
    spec["inference"]["burn_in"] = 0            # a bool where the setting is one stays accepted
    path.write_text(yaml.safe_dump(spec))
    assert load_model_spec(str(path)).inference.jit is True


@pytest.mark.parametrize("key, name", [("prior", "ising"), ("likelihood", "gaussian")])
def test_a_prior_or_likelihood_given_by_its_name_alone_is_shown_the_mapping_it_needs(tmp_path, key, name):
    path = tmp_path / "n.yaml"
    path.write_text(yaml.safe_dump({"name": "n", "subgoals": ["a", "goal"], "edges": [["a", "goal", "positive"]],
                                    key: name}))
    with pytest.raises(SpecError, match=rf"n.yaml: {key}: write {{name: {name}}}, with any parameters") as err:
        load_model_spec(str(path))
    assert "ComponentSpec" not in str(err.value) and "\n" not in str(err.value)
