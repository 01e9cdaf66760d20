"""The agents' settings, typed: one pydantic model per section, each range declared once on its field,
and each task family's defaults as a constructor of the model (``LoopConfig.minigrid()``,
``LoopConfig.robosuite()``, ...).

=========  =====================================================================================
section    settings
=========  =====================================================================================
``loop``   :class:`LoopConfig` (the HRL loop; ``total_steps`` comes from the run's ``steps``)
``high``   :class:`HighLevelConfig`
``low``    :class:`GoalDQNConfig` (learned grid low level), :class:`GoalTD3Config` (learned arm low
           level), :class:`ScriptedMazeConfig` or :class:`ScriptedOSCConfig` (scripted low levels)
``hiro``   :class:`HIROConfig` (``total_steps`` comes from ``steps``)
``higl``   :class:`HIGLConfig`: HIRO's settings and the landmarks'
``dqn``,   keyword arguments of Stable-Baselines3's DQN, PPO, TD3 (:func:`sb3_model`), plus
``ppo``,   ``unit_steps`` (:mod:`.flat`) and, for ``td3``, ``noise_sigma``
``td3``
=========  =====================================================================================

A class default is the value of a setting no family sets; a family constructor sets only what that
family changes, so ``model_dump(exclude_unset=True)`` of it is the family's section as
:mod:`.presets` lists it. :func:`validate` turns the first problem into one line naming the key, what
it takes (kind and range) and its default. A number written ``3e-4`` (YAML reads it as text) is a
number for a numeric setting. This module imports nothing from the rest of the package.
"""

from __future__ import annotations

import functools
import inspect
from typing import Annotated, Any, Literal, Optional

from pydantic import (BaseModel, BeforeValidator, ConfigDict, Field, StrictBool, StrictFloat, StrictInt,
                      ValidationError, create_model)

__all__ = ["ConfigError", "Settings", "LoopConfig", "HighLevelConfig", "GoalDQNConfig", "GoalTD3Config",
           "HIROConfig", "HIGLConfig", "ScriptedMazeConfig", "ScriptedOSCConfig", "DERIVED", "sb3_model", "validate",
           "describe"]

#: set by the builders from the run's ``steps``, never in a section
DERIVED = ("total_steps",)


class ConfigError(ValueError):
    """A setting is unknown, of the wrong kind or out of range; ``section``/``key`` name it (section None:
    the run's own settings)."""

    def __init__(self, message: str, section: str | None, key: str):
        super().__init__(message)
        self.section, self.key = section, key


# -- value types: each carries what it takes in words (its description) --------------------------------


def _number(text: Any) -> Any:
    """``"3e-4"`` (text to YAML) -> 0.0003; anything else unchanged."""
    if isinstance(text, str):
        try:
            return float(text)
        except ValueError:
            return text
    return text


def _integer(text: Any) -> Any:
    """``"1e5"`` -> 100000; a text that is not a whole number stays text (and is refused)."""
    value = _number(text)
    return int(value) if isinstance(value, float) and isinstance(text, str) and value.is_integer() else text


def _any_number(text: Any) -> Any:
    """For a setting of any kind (SB3's): a number written as text becomes an int if whole, else a float."""
    value = _integer(text)
    return _number(value) if isinstance(value, str) else value


def _range(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    if lo is not None and hi is not None:
        return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo:g}"
    return "" if hi is None else f" {'<' if hi_open else '<='} {hi:g}"


def integer(ge: int | None = None) -> Any:
    """An integer (``"1e5"`` accepted), at least ``ge``."""
    return Annotated[StrictInt, BeforeValidator(_integer),
                     Field(ge=ge, description="an integer" + _range(ge, None, False, False))]


def number(lo: float | None = None, hi: float | None = None, lo_open: bool = False, hi_open: bool = False) -> Any:
    """A finite number (``"3e-4"`` accepted) in the range given (``*_open``: the bound itself excluded)."""
    bounds = {("gt" if lo_open else "ge"): lo, ("lt" if hi_open else "le"): hi}
    return Annotated[StrictFloat, BeforeValidator(_number),
                     Field(allow_inf_nan=False, description=("a number" if hi is not None else "a finite number")
                           + _range(lo, hi, lo_open, hi_open),
                           **{k: v for k, v in bounds.items() if v is not None})]


def choice(*values: str) -> Any:
    return Annotated[Literal[values], Field(description="one of " + ", ".join(map(repr, values)))]


def optional(kind: Any) -> Any:
    """``kind`` or null."""
    return Annotated[kind | None, Field(description=_text(kind) + ", or null")]


def _text(kind: Any) -> str:
    return next(m.description for m in kind.__metadata__ if getattr(m, "description", None))


Flag = Annotated[StrictBool, Field(description="true or false")]
Sizes = Annotated[tuple[integer(1), ...], Field(description="a list of integers >= 1, e.g. [64, 64]")]
Rate = number(0, lo_open=True)                  # a learning rate, a tolerance, a scale: > 0
Share = number(0, 1)                            # a probability or an ε: in [0, 1]
Fraction = number(0, 1, lo_open=True)           # a share of the budget, of an interval: in (0, 1]
Count = integer(1)
Starts = integer(0)
Discount = number(0, 1)
Polyak = number(0, 1, lo_open=True)
NonNegative = number(0)


class Settings(BaseModel):
    """A section's settings: unknown keys are refused; assignment is not re-validated (the run harness
    sets ``total_steps`` and ``eval_break_cycles`` on a built agent)."""

    model_config = ConfigDict(extra="forbid")


# -- the sections ------------------------------------------------------------------------------------


class LoopConfig(Settings):
    """The HRL loop (:mod:`.loop`)."""

    total_steps: Count = 100_000                 # the run's steps (derived)
    option_steps: Count = 40                     # N: low-level steps per high-level decision
    gamma: Discount = 0.99                       # per primitive step (the high level discounts by γ^k)
    explore_start: Share = 1.0                   # high-level ε-greedy exploration (decays)
    explore_end: Share = 0.05
    explore_fraction: Fraction = 0.3
    low_explore_start: Share = 1.0               # low-level ε-greedy exploration (decays)
    low_explore_end: Share = 0.05
    low_explore_fraction: Fraction = 0.3
    filter_start: Share = 0.0                    # Sec. 3.4: probability of choosing from Ĝt (rises)
    # below 1, so that a share of the high level's decisions always reads G0: one of the two guards
    # against a critic that learns nonsense (the other is filter_keep; agents/filters.py)
    filter_end: Share = 0.9
    filter_fraction: Fraction = 0.5
    # the filter keeps the achieved sets of the last outcome_window successful episodes (the evidence
    # of outcome likelihoods); Ĝt always holds the sub-goals achieved in at least filter_keep of them
    # (1: in every one of them; 0 turns the safeguard off)
    outcome_window: Count = 20
    filter_keep: Share = 1.0
    # Ĝt before the critic's first update: "g0" (no filter) or "completion" (q's completion of the
    # achieved sub-goals, q being the prior then; CriticFilter.allowed)
    filter_before_update: choice("g0", "completion") = "g0"
    # "uniform": the learned low level's TD loss weighs every sub-goal alike (h-DQN's all-goal
    # relabelling); "marginal" (with a critic and the learned grid low level; "uniform" without them):
    # after each critic update from evidence a sub-goal weighs its marginal P(w_g = 1), at least
    # 1 - filter_end (the share of choices that still read G0)
    low_goal_weight: choice("uniform", "marginal") = "uniform"
    critic_every: Count = 1                      # high-level minibatches pooled into one critic update
    filter_refresh: choice("option", "episode") = "option"     # when the loop reads Ĝt
    # Ĝt given the evidence: the mode of the critic's samples among those that include every sub-goal
    # achieved at the time (CriticFilter.allowed), for choosing and for each TD target's s'. False: the
    # paper's unconditional mode
    filter_given_achieved: Flag = False
    # While training, a low-level step in a state where the greedy low level already acted under the
    # same sub-goal in this episode is taken at random (a greedy cycle in a deterministic env never
    # ends by itself). Discrete action spaces with a learned low level only
    low_break_cycles: Flag = True
    # greedy evaluation breaks the low level's cycles by the same rule (``hubsgo evaluate
    # --no-break-cycles`` evaluates the bare greedy policy)
    eval_break_cycles: Flag = True
    # The agent settles at the end of the first episode at which its success rate over its last
    # outcome_window training episodes (a full window) reaches settle_at; from then on G* is read from
    # the critic refitted for settle_updates updates on the recent successes (HRLLoop.g_star_critic).
    # Training is the same with or without settling. None: never settles
    settle_at: optional(number(0, 1, lo_open=True)) = 0.9
    settle_updates: Count = 300

    @classmethod
    def minigrid(cls) -> "LoopConfig":
        """The mazes' loop: Ĝt read given what the agent holds, once per episode until that changes;
        before the critic's first update the prior's completion of what was achieved; a critic update
        every 4th high-level minibatch; the low level's loss weighted by the critic's marginals."""
        return cls(option_steps=10, explore_fraction=0.3, low_explore_fraction=0.3, filter_start=0.5,
                   filter_end=0.9, filter_fraction=0.3, filter_given_achieved=True, filter_refresh="episode",
                   filter_before_update="completion", critic_every=4, low_goal_weight="marginal")

    @classmethod
    def robosuite(cls) -> "LoopConfig":
        """The arms' loop: 60-step options fit any single scripted sub-goal (measured <= 45 for grasp
        and place); the low-level ε scales GoalTD3's exploration noise (the scripted controller ignores it)."""
        return cls(option_steps=60, explore_fraction=0.3, filter_fraction=0.3, low_explore_start=1.0,
                   low_explore_end=0.3, low_explore_fraction=0.5)


class HighLevelConfig(Settings):
    """The high level's DQN (:mod:`.high_level`)."""

    hidden: Sizes = (128, 128)
    lr: Rate = 1e-3
    gamma: Discount = 0.99         # per primitive step; an option of k steps discounts by γ^k (SMDP)
    batch_size: Count = 64
    buffer_size: Count = 20_000
    learning_starts: Starts = 64   # high-level transitions before updates start
    target_tau: Polyak = 0.02      # Polyak rate of the target network
    double_q: Flag = True
    grad_clip: Rate = 10.0

    @classmethod
    def minigrid(cls) -> "HighLevelConfig":
        return cls(hidden=(128, 128), lr=1e-3, batch_size=64)

    @classmethod
    def robosuite(cls) -> "HighLevelConfig":
        return cls(hidden=(128, 128), lr=1e-3, batch_size=32, learning_starts=32)


class GoalDQNConfig(Settings):
    """The learned grid low level (:class:`~.low_level.GoalDQN`)."""

    hidden: Sizes = (256, 256)
    lr: Rate = 5e-4
    gamma: Discount = 0.95
    batch_size: Count = 128
    buffer_size: Count = 100_000
    learning_starts: Starts = 1_000
    train_every: Count = 2         # env steps per gradient step
    target_tau: Polyak = 0.01
    grad_clip: Rate = 10.0
    # potential-based shaping of the intrinsic reward, r + shaping * (gamma * phi(s') - phi(s)), with the
    # env's subgoal_potential (Ng et al. 1999: optimal policies unchanged); 0 turns it off
    shaping: NonNegative = 0.0

    @classmethod
    def minigrid(cls) -> "GoalDQNConfig":
        """Potential-based shaping towards each sub-goal's cell."""
        return cls(hidden=(128, 128), lr=5e-4, batch_size=128, learning_starts=1000, shaping=1.0)

    @classmethod
    def gym(cls) -> "GoalDQNConfig":
        """The mazes' low level without shaping (a user's env has no subgoal_potential)."""
        return cls(hidden=(128, 128), lr=5e-4, batch_size=128, learning_starts=1000)


class GoalTD3Config(Settings):
    """The learned arm low level (:class:`~.td3_her.GoalTD3`); the defaults are the configuration
    benchmarks/reach_skill.py measured."""

    hidden: Sizes = (128, 128)
    actor_lr: Rate = 1e-3
    critic_lr: Rate = 1e-3
    gamma: number(0, 1, hi_open=True) = 0.95    # per low-level step; HER's value for short-horizon reaching
    tau: Polyak = 0.05               # Polyak rate of the target networks (HER: 0.95 retention)
    batch_size: Count = 128
    buffer_size: Count = 200_000
    learning_starts: Starts = 500    # stored transitions (relabelled included) before updates start
    train_every: Count = 1           # env steps per gradient step (2: held-out reach 0.40 against 1.00 at 3,000 steps)
    gradient_steps: Count = 1        # gradient steps each time training triggers
    policy_delay: Count = 2          # TD3: one actor update per this many critic updates
    target_noise: NonNegative = 0.2  # TD3 target policy smoothing (fraction of the action range)
    target_noise_clip: NonNegative = 0.5
    noise_sigma: NonNegative = 0.2   # Gaussian exploration std at explore_eps = 1 (fraction of range)
    random_eps: Share = 0.3          # uniform random action with probability random_eps * explore_eps
    action_l2: NonNegative = 0.1     # HER's penalty on the actor's (normalised) actions
    her_k: Starts = 4                # relabelled copies per transition ('future' strategy)
    tolerance: Rate = 0.01           # metres: the target region's radius, inside the arm interface's 1.5 cm
    #                                  grip trigger (a hand 2 cm off never closes on its object)
    gripper_tolerance: Rate = 0.5    # |applied - commanded| gripper within this counts as reached
    goal_scale: Rate = 10.0          # relative goal (m) times this is the network input
    use_obs: Flag = False            # also feed the (normalised) observation, not only the goal
    obs_clip: Rate = 5.0
    # the task-agnostic reach skill the networks start from (hubsgo_ppl/agents/reach_skill.pt, trained by
    # benchmarks/reach_skill.py --save); null: from scratch
    skill: Optional[Literal["reach"]] = "reach"


class ScriptedMazeConfig(Settings):
    """The scripted grid low level (:class:`~.scripted_maze.ScriptedMaze`)."""

    max_states: Count = 200_000      # breadth-first search gives up past this many states


class ScriptedOSCConfig(Settings):
    """The scripted arm low level (:class:`~.scripted_osc.ScriptedOSC`)."""

    gain: Rate = 20.0                # action per metre
    tolerance: NonNegative = 0.002   # metres


class HIROConfig(Settings):
    """HIRO (:mod:`.hiro`)."""

    total_steps: Count = 100_000
    c: Count = 10                       # env steps per high-level goal
    gamma_high: Discount = 0.99         # per high-level step
    gamma_low: Discount = 0.95
    hidden: Sizes = (128, 128)
    lr: Rate = 3e-4
    batch_size: Count = 64
    tau: Polyak = 0.005
    high_buffer: Count = 5_000
    low_buffer: Count = 50_000
    high_learning_starts: Starts = 32   # high-level transitions before the high level learns
    low_learning_starts: Starts = 500   # low-level transitions before the low level learns
    high_noise: NonNegative = 0.2       # exploration noise on goals (fraction of scale)
    low_noise: NonNegative = 0.1        # TD3 low level: exploration noise (fraction of action range)
    temperature: Rate = 0.3             # DQN low level: Boltzmann temperature τ
    candidates: Starts = 8              # Gaussian relabelling candidates
    candidate_sigma: NonNegative = 0.5  # their std (fraction of scale), as in Nachum et al.
    goal_scale: optional(Rate) = None   # None: the task family's default
    policy_noise: NonNegative = 0.2     # TD3 target smoothing
    noise_clip: NonNegative = 0.5
    policy_delay: Count = 2

    @classmethod
    def minigrid(cls) -> "HIROConfig":
        """Goals are (dx, dy) cell offsets."""
        return cls(c=10, hidden=(128, 128), lr=3e-4, batch_size=64, low_learning_starts=1000,
                   temperature=0.3, high_noise=0.3)

    @classmethod
    def robosuite(cls) -> "HIROConfig":
        """Goals are end-effector offsets (m) within +-goal_scale."""
        return cls(c=10, hidden=(256, 256), lr=3e-4, batch_size=128, low_learning_starts=1000,
                   goal_scale=0.3, low_noise=0.1)


class HIGLConfig(HIROConfig):
    """HIGL (:mod:`.higl`): HIRO's settings, and the landmarks that guide its high level."""

    landmarks_coverage: Count = 20      # by farthest-point sampling over the pool
    landmarks_novelty: Starts = 10      # the least-visited states
    landmark_pool: Count = 400          # replayed states the coverage landmarks are chosen from
    landmark_cutoff: Rate = 5.0         # graph edges longer than this (low-level value) are removed
    landmark_step: Fraction = 1.0       # the pseudo-landmark's largest distance from the state (fraction of scale)
    landmark_weight: NonNegative = 0.1  # of the landmark loss in the high level's actor loss (0: HIRO)
    novelty_cell: optional(Rate) = None  # goal-space cell of the visit counts; None: 1 (a grid cell)
    graph_every: Count = 10             # high-level actor updates between landmark graph rebuilds

    @classmethod
    def robosuite(cls) -> "HIGLConfig":
        """HIRO's arm settings; visit counts over 5 cm cells."""
        return cls(**HIROConfig.robosuite().model_dump(exclude_unset=True), novelty_cell=0.05)


# -- Stable-Baselines3's sections ----------------------------------------------------------------------

#: the trainer's own settings of a flat baseline's section (not SB3's), with what they take
_SB3_EXTRA = {"dqn": {"unit_steps": Count}, "ppo": {"unit_steps": Count},
              "td3": {"unit_steps": Count, "noise_sigma": NonNegative}}
#: SB3 constructor arguments the trainer sets itself
_SB3_FIXED = {"policy", "env", "seed", "verbose", "device", "_init_setup_model"}
#: ranges of SB3's numeric arguments (any other argument takes any value, a number written as text
#: converted); SB3 takes a tuple for train_freq too
_SB3_RANGES = {"learning_rate": Rate, "buffer_size": Count, "learning_starts": Starts, "batch_size": Count,
               "target_update_interval": Count, "n_steps": Count, "n_epochs": Count, "gamma": Discount,
               "tau": Polyak, "exploration_fraction": Fraction, "exploration_initial_eps": Share,
               "exploration_final_eps": Share}
AnyValue = Annotated[Any, BeforeValidator(_any_number)]


@functools.cache
def sb3_model(section: str) -> type[Settings]:
    """The model of the ``dqn``, ``ppo`` or ``td3`` section: SB3's constructor arguments and the extras."""
    import stable_baselines3 as sb3

    algo = getattr(sb3, section.upper())
    names = [p for p in inspect.signature(algo.__init__).parameters if p != "self" and p not in _SB3_FIXED]
    fields = {name: (_SB3_RANGES.get(name, AnyValue), None) for name in names}
    fields.update({name: (optional(kind), None) for name, kind in _SB3_EXTRA[section].items()})
    return create_model(f"{section.upper()}Settings", __base__=Settings, **fields)


# -- validation -------------------------------------------------------------------------------------------


def describe(model: type[BaseModel], key: str) -> str:
    """What ``model``'s setting ``key`` takes, in words (kind and range)."""
    return model.model_fields[key].description or "a valid value"


def validate(section: str, model: type[Settings], values: Any, defaults: dict[str, Any] | None = None,
             agent: str | None = None, derived: dict[str, Any] | None = None) -> Settings:
    """``model`` built from ``values`` (and ``derived``: the keys the builder sets itself, such as
    ``total_steps``, which a section may not hold). The first problem is a :class:`ConfigError` of one
    line: an unknown key with the valid ones, or a bad value with what the key takes and its default
    (the one in ``defaults``, else the model's). ``section=""``: the run's own settings."""
    name = f"{section}." if section else ""
    if not isinstance(values, dict):
        raise ConfigError(f"section {section!r} must be a mapping of settings, got {values!r}", None, section)
    valid = sorted(k for k in model.model_fields if k not in DERIVED)
    unknown = [k for k in values if k not in valid]
    if unknown:
        who = f" (agent {agent})" if agent else ""
        raise ConfigError(f"unknown key {str(unknown[0])!r} in section {section!r}{who}; valid keys: "
                          f"{', '.join(valid)}", section, str(unknown[0]))
    try:
        return model.model_validate({**values, **(derived or {})})
    except ValidationError as exc:
        key = str(exc.errors()[0]["loc"][0])
        default = (defaults or {}).get(key, model.model_fields[key].default)
        got = values.get(key, (derived or {}).get(key))
        raise ConfigError(f"{name}{key} takes {describe(model, key)} (default {default!r}), got {got!r}",
                          section or None, key) from None
