"""Declarative specs: YAML files -> validated, typed objects.

Every spec error is a :class:`SpecError` whose message names the file, the key and a fix, e.g.::

    models/keydoor.yaml: edges[2]: 'blue_dor' is not in subgoals; subgoals lists 'blue_door': correct ...

Specs are strict (unknown keys are errors), following Pyro's habit of rejecting unrecognised options.
An error never prints back a file that is not a spec: a file that is not a YAML mapping, or whose
keys are none of the spec's, gets one line naming the file and what the spec is; the keys and values
of a spec are shown shortened (:mod:`hubsgo_ppl.validation`).
"""

from __future__ import annotations

import difflib
from pathlib import Path
from typing import Any, ClassVar, TypeVar

import yaml
from pydantic import BaseModel, ConfigDict, ValidationError, field_validator

from .errors import SpecError
from .validation import KEY_CHARS, VALUE_CHARS, format_validation_error, no_bool_as_number, shorten

__all__ = ["SpecError", "StrictModel", "load_yaml", "validate_spec", "format_validation_error"]

M = TypeVar("M", bound=BaseModel)


class StrictModel(BaseModel):
    """Base for spec objects: unknown keys are rejected, values are validated on assignment.
    ``spec_kind`` names what a file of this model is, and ``spec_example`` points at one, in the line
    that refuses a file that is not one."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)
    spec_kind: ClassVar[str] = "spec"
    spec_example: ClassVar[str] = ""

    _no_bool_as_number = field_validator("*", mode="before")(classmethod(no_bool_as_number))


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, refusing a key given twice in one mapping (where YAML keeps the last)."""

    def construct_mapping(self, node: Any, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {shorten(repr(key), KEY_CHARS)}: give each key once",
                    key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def load_yaml(path: str | Path, what: str = "spec") -> dict[str, Any]:
    """Read a YAML mapping, with errors that name the file and say what a ``what`` is, never its content."""
    path = Path(path)
    if path.is_dir():
        raise SpecError(f"{path}: a directory, not a {what} file; pass the path of the YAML file itself")
    if not path.is_file():
        raise SpecError(f"{path}: no such {what} file; check the path or use a built-in name")
    try:
        data = yaml.load(path.read_text(encoding="utf-8"), Loader=_UniqueKeyLoader)
    except UnicodeDecodeError as exc:
        raise SpecError(f"{path}: not UTF-8 text (byte {exc.start}); save it as UTF-8 (a {what} is a YAML mapping "
                        "of keys)") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        what_went_wrong = getattr(exc, "problem", None) or " ".join(str(exc).split())
        context = getattr(exc, "context", None)
        said = shorten(f"{what_went_wrong}{', ' + context if context else ''}", 100)   # YAML quotes the file
        raise SpecError(f"{path}: not valid YAML ({where}{said}); fix the syntax (a {what} is a YAML mapping "
                        "of keys)") from None
    if not isinstance(data, dict):
        held = {str: "text", list: "a list", type(None): "nothing"}.get(type(data), type(data).__name__)
        raise SpecError(f"{path}: not a {what}: a {what} is a YAML mapping of keys, and this file holds {held}; "
                        "check the path")
    return data


def _not_a_spec(cls: type[BaseModel], source: str) -> str:
    kind = getattr(cls, "spec_kind", "spec")
    example = getattr(cls, "spec_example", "")
    keys = [name for name, field in cls.model_fields.items() if not field.exclude]
    return (f"{source}: not a {kind}: a {kind} is a YAML mapping with the keys {', '.join(keys)}, "
            f"and this file has none of them{f' ({example} is an example)' if example else ''}; check the path")


def validate_spec(cls: type[M], data: dict[str, Any], source: str = "<spec>") -> M:
    """Validate ``data`` into ``cls``; raise :class:`SpecError` naming ``source`` and each bad key. A
    mapping none of whose keys is one of ``cls``'s is not a spec: one line says so, naming none of them."""
    if isinstance(data, dict) and data and not any(isinstance(k, str) and k in cls.model_fields for k in data):
        raise SpecError(_not_a_spec(cls, source))
    try:
        return cls.model_validate(data)
    except ValidationError as err:
        raise SpecError(format_validation_error(source, err)) from None


# ---------------------------------------------------------------------------------------------
# Critic model specs (models/*.yaml): sub-goals, signed edges, prior, likelihood, inference.
# ---------------------------------------------------------------------------------------------

from typing import Literal  # noqa: E402

from pydantic import ConfigDict as _ConfigDict  # noqa: E402
from pydantic import Field, field_validator, model_validator  # noqa: E402

# The critic's settings are defined by the critic's package (pydantic only, no torch), so that specs
# depend on infer and never the other way round. The registries of priors and likelihoods import
# Pyro, so the validators below import them when they run, not when this module loads.
from .infer.config import InferenceSpec  # noqa: E402

__all__ += ["ComponentSpec", "DEFAULT_LIKELIHOOD", "DEFAULT_PRIOR", "FAMILY_LIKELIHOOD", "InferenceSpec", "ModelSpec",
            "for_family", "load_model_spec", "list_model_specs", "match_subgoals"]

EdgeSign = Literal["positive", "negative", "unknown"]


class ComponentSpec(BaseModel):
    """A registered prior or likelihood: ``{name: ..., **params}``."""

    model_config = _ConfigDict(extra="allow")
    name: str = Field(description="registered name, e.g. 'bernoulli' or 'gaussian'")

    @model_validator(mode="before")
    @classmethod
    def _a_mapping(cls, value: Any) -> Any:
        if isinstance(value, str):      # `prior: ising`: the name alone, where a mapping is due
            raise ValueError(f"write {{name: {value}}}, with any parameters beside the name")
        return value

    def params(self) -> dict[str, Any]:
        return dict(self.model_extra or {})


# What a spec that leaves out ``prior``, ``likelihood`` or ``inference.init`` gets: the critic every
# shipped maze spec states (docs/results.md, "Critic evidence and defaults"). The human's signed edges
# become the prior's couplings, a negative field favours small sets, the evidence is the sub-goals
# that recent successful episodes achieved, and q starts at the prior.
DEFAULT_PRIOR = {"name": "ising", "strength": 3.0, "field": -2.0}
DEFAULT_LIKELIHOOD = {"name": "outcome", "flip": 0.02}
#: a task family's own likelihood for a spec that leaves it out (:func:`for_family`): on the arm tasks
#: the successes speak at full weight, as every shipped arm spec states (docs/results.md, "How strongly
#: the successes speak"); there an option is a whole pick-and-place, not one cell of a route
FAMILY_LIKELIHOOD = {"robosuite": {"name": "outcome", "flip": 0.02, "power": 1.0}}


#: the sizes a prior's or likelihood's number may take (or 0): the critic computes in float32, where
#: a field of -1e39 overflows and a scale of 1e-320 is 0, and far inside those limits a probability
#: has long saturated
PARAM_RANGE = (1e-9, 1e9)


def _float_params(kind: str, name: str) -> set[str]:
    """The parameters of a registered prior or likelihood whose defaults are numbers."""
    import inspect

    if kind == "prior":
        from .infer.priors import PRIORS as table
    else:
        from .infer.likelihoods import LIKELIHOODS as table
    cls = table.get(name)
    if cls is None:
        return set()
    return {p.name for p in inspect.signature(cls.__init__).parameters.values()
            if isinstance(p.default, (int, float)) and not isinstance(p.default, bool)}


def _numbers_in_range(kind: str, v: ComponentSpec) -> ComponentSpec:
    lo, hi = PARAM_RANGE
    numeric = _float_params(kind, v.name)
    for key, value in v.params().items():
        if isinstance(value, bool) and key in numeric:
            raise ValueError(f"{v.name!r}: {key} takes a number, got {value!r}")
        if isinstance(value, bool) or not isinstance(value, (int, float, str)):
            continue        # another type is the component's own to check
        try:
            x = abs(float(value))       # YAML reads 1e-3 (no dot) as text; the components take it as a number
        except ValueError:
            continue
        if not (x == 0 or lo <= x <= hi):       # NaN fails both
            raise ValueError(f"{v.name!r}: {key} = {shorten(repr(value), VALUE_CHARS)} is out of range; give a "
                             f"number between {lo:g} and {hi:g} in size, or 0")
    return v


def own_component(kind: str, name: str) -> None:
    """Register the prior or likelihood class a spec names as ``module:Class`` (a user's own, importable
    from an installed package or ``PYTHONPATH``) under that name, so the critic builds it as it builds
    the registered ones; a name without ``:`` is left to the registry."""
    import importlib

    from .infer import likelihoods, priors

    if kind == "prior":
        table, base = priors.PRIORS, priors.Prior
    else:
        table, base = likelihoods.LIKELIHOODS, likelihoods.Likelihood
    module, sep, qualname = name.partition(":")
    if not sep or name in table:
        return
    if not module or not qualname:
        raise ValueError(f"{kind} {name!r}: name a class of your own as 'module:Class', e.g. 'my_pkg.priors:Sparse'")
    try:
        obj = importlib.import_module(module)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except ModuleNotFoundError as exc:
        raise ValueError(f"{kind} {name!r}: cannot import {module!r} ({exc}); install its package or add its "
                         "folder to PYTHONPATH") from None
    except AttributeError:
        raise ValueError(f"{kind} {name!r}: module {module!r} has no {qualname!r}; check the name") from None
    if not (isinstance(obj, type) and issubclass(obj, base)):
        what = "a class" if isinstance(obj, type) else f"a {type(obj).__name__}"
        raise ValueError(f"{kind} {name!r} is {what}, not a subclass of hubsgo_ppl.infer.{base.__name__}")
    table[name] = obj
    if "registered_name" not in vars(obj):      # not also registered under a short name of its own
        obj.registered_name = name


class ModelSpec(StrictModel):
    """A critic spec; see models/example-specific.yaml.

    Left out, ``prior`` and ``likelihood`` are :data:`DEFAULT_PRIOR` and :data:`DEFAULT_LIKELIHOOD`
    (a run then gives the likelihood of its task's family, :func:`for_family`), and ``inference.init``
    is ``prior`` where the guide can start at the prior (it has natural parameters, as bernoulli and
    ising do), ``edges`` otherwise; every other inference setting keeps its :class:`InferenceSpec`
    default.
    """

    spec_kind: ClassVar[str] = "critic spec"
    spec_example: ClassVar[str] = "models/keydoor-specific.yaml"

    name: str
    task: str | None = None
    subgoals: list[str]
    graph: Literal["specific", "fully_connected", "independent"] = "specific"
    edges: list[tuple[str, str, EdgeSign]] = Field(default_factory=list)
    prior: ComponentSpec = Field(default_factory=lambda: ComponentSpec(**DEFAULT_PRIOR))
    likelihood: ComponentSpec = Field(default_factory=lambda: ComponentSpec(**DEFAULT_LIKELIHOOD))
    inference: InferenceSpec = Field(default_factory=InferenceSpec)

    @field_validator("name")
    @classmethod
    def _name_ok(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("the spec's name is empty; name it (e.g. after its task and graph)")
        return v

    @field_validator("subgoals")
    @classmethod
    def _subgoals_ok(cls, v: list[str]) -> list[str]:
        if not v:
            raise ValueError("no sub-goals (N = 0); list at least one candidate sub-goal")
        seen: set[str] = set()
        for i, name in enumerate(v):
            if not name:
                raise ValueError(f"subgoals[{i}] is empty; give every sub-goal a name")
            if name in seen:
                raise ValueError(f"subgoals[{i}]: duplicate name {name!r}; names must be unique")
            seen.add(name)
        return v

    @field_validator("prior")
    @classmethod
    def _prior_ok(cls, v: ComponentSpec) -> ComponentSpec:
        from .infer.priors import PRIORS

        own_component("prior", v.name)
        if v.name not in PRIORS:
            name = shorten(repr(v.name), KEY_CHARS)
            raise ValueError(f"unknown prior {name}; registered: {', '.join(sorted(PRIORS))}")
        return _numbers_in_range("prior", v)

    @field_validator("likelihood")
    @classmethod
    def _likelihood_ok(cls, v: ComponentSpec) -> ComponentSpec:
        from .infer.likelihoods import get_likelihood

        own_component("likelihood", v.name)
        _numbers_in_range("likelihood", v)
        try:
            get_likelihood(v.name, **v.params())  # ValueError names the bad key, or lists registered names
        except TypeError as exc:
            raise ValueError(f"likelihood {v.name!r}: {exc}; give each parameter a number") from None
        return v

    @model_validator(mode="after")
    def _graph_ok(self) -> "ModelSpec":
        names = set(self.subgoals)
        pairs: dict[frozenset[str], str] = {}
        for i, (u, v, sign) in enumerate(self.edges):
            for end in (u, v):
                if end not in names:
                    close = difflib.get_close_matches(end, self.subgoals, n=1)
                    hint = (f"; subgoals lists {close[0]!r}: correct the spelling in whichever of the two is wrong"
                            if close else "")
                    raise ValueError(f"edges[{i}]: {end!r} is not in subgoals{hint}; use one of: "
                                     f"{', '.join(self.subgoals)}")
            if u == v:
                raise ValueError(f"edges[{i}]: self-edge on {u!r}; an edge joins two different sub-goals")
            earlier = pairs.get(frozenset((u, v)))
            if earlier is not None and earlier != sign:
                raise ValueError(f"edges[{i}]: {u!r}-{v!r} is given both {earlier!r} and {sign!r}; keep the sign you "
                                 "believe, or 'unknown' where you do not know")
            if earlier is not None:
                raise ValueError(f"edges[{i}]: duplicate edge {u!r}-{v!r}; give each pair once")
            pairs[frozenset((u, v))] = sign
        from .graph import SubgoalGraph
        from .infer.priors import get_prior

        try:
            prior = get_prior(self.prior.name, SubgoalGraph(self.subgoals), **self.prior.params())
        except (TypeError, ValueError) as exc:     # a parameter of the wrong type (text or a list for a number)
            params = shorten(str(self.prior.params()), VALUE_CHARS)
            raise ValueError(f"prior {self.prior.name!r} {params}: {exc}; give each parameter a number") from None
        from .infer.likelihoods import check_likelihood, get_likelihood
        from .infer.priors import check_prior

        check_prior(prior)                                  # a user's own: its distribution() can serve the critic
        check_likelihood(get_likelihood(self.likelihood.name, **self.likelihood.params()), len(self.subgoals))
        holds_prior = prior.natural_params() is not None    # a pairwise MRF the guide can start equal to
        if "init" not in self.inference.model_fields_set:    # left out: start at the prior where the guide can
            self.inference.init = "prior" if holds_prior else "edges"
        elif self.inference.init == "prior" and not holds_prior:
            raise ValueError(f"inference.init 'prior' needs a prior the guide (a pairwise MRF) can start equal to, "
                             f"such as bernoulli or ising, and {self.prior.name!r} is not one; use init: edges, "
                             f"or leave init out")
        return self


def match_subgoals(spec: ModelSpec, names: list[str], source: str) -> ModelSpec:
    """``spec`` with its sub-goals in the task catalogue's order ``names``, matched by name (a spec may
    list them in any order; edges name their ends, so they need no change). A spec that names a
    sub-goal the catalogue lacks is refused with those names (a spec may list a subset of the task's
    sub-goals, and no others); one that leaves some out is refused here, where all are matched (a subset
    is a run's candidates: ``experiments.resolve``)."""
    missing = [n for n in names if n not in spec.subgoals]
    extra = [n for n in spec.subgoals if n not in names]
    if extra:
        left = f" (it leaves out {', '.join(missing)})" if missing else ""
        raise SpecError(f"{source}: subgoals: not in the task: {', '.join(extra)}{left}; a spec lists the task's "
                        f"sub-goals, all of them or some, in any order, and no others: {', '.join(names)}")
    if missing:
        raise SpecError(f"{source}: subgoals: missing {', '.join(missing)}; matched by name, a spec lists every "
                        f"one of the task's sub-goals, in any order: {', '.join(names)}")
    if list(spec.subgoals) == list(names):
        return spec
    return spec.model_copy(update={"subgoals": list(names)})


def for_family(spec: ModelSpec, family: str) -> ModelSpec:
    """``spec`` for a task of ``family``: where the spec leaves its likelihood out and the family has its
    own (:data:`FAMILY_LIKELIHOOD`), that one; a likelihood the spec states is always kept."""
    own = FAMILY_LIKELIHOOD.get(family)
    if own is None or "likelihood" in spec.model_fields_set:
        return spec
    return spec.model_copy(update={"likelihood": ComponentSpec(**own)})


def list_model_specs() -> list[str]:
    """Names of the built-in critic specs (``models/*.yaml``)."""
    from .resources import models_dir

    return sorted(p.stem for p in models_dir().glob("*.yaml"))


def load_model_spec(name_or_path: str | Path, graph: str | None = None) -> ModelSpec:
    """Load a critic spec by built-in name (any cwd) or by path; ``graph`` overrides the preset."""
    from .resources import models_dir

    path = Path(name_or_path)
    if not path.is_file():
        builtin = models_dir() / f"{name_or_path}.yaml"
        if builtin.is_file():
            path = builtin
        elif path.is_dir():
            raise SpecError(f"{path}: a directory, not a spec file; pass the path of a critic spec's YAML file, or a "
                            f"built-in name: {', '.join(list_model_specs())}")
        elif path.suffix in (".yaml", ".yml") or path.parent != Path("."):
            raise SpecError(f"{path}: no such spec file; check the path or use a built-in name: {', '.join(list_model_specs())}")
        else:
            raise SpecError(f"{name_or_path}: unknown model spec; use a path or one of: {', '.join(list_model_specs())}")
    data = load_yaml(path, what=ModelSpec.spec_kind)
    if graph is not None:
        data = {**data, "graph": graph}
    return validate_spec(ModelSpec, data, source=str(path))
