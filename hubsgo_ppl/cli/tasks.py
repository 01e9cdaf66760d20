"""``hubsgo tasks``: list the tasks, or check a task (and a critic spec) as ``hubsgo train`` would."""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from typing import Any

__all__ = ["cmd_tasks", "cmd_check_env"]


def cmd_tasks(args: argparse.Namespace) -> int:
    from ..envs import get_task, tasks

    if args.model is not None and not args.task:
        from ..experiments.run import RunError

        raise RunError("--model checks a spec against the tasks named: `hubsgo tasks TASK --model SPEC`")
    chosen = {str(t): get_task(t) for t in args.task} if args.task else tasks()
    for name, info in chosen.items():
        cat = info.catalogue
        print(f"{name}  ({info.family}, gymnasium id {info.env_id})")
        if cat.description:
            print(f"    {cat.description.strip()}")
        for sg in cat.subgoals:
            desc = f": {sg.description}" if sg.description else ""
            print(f"    - {sg.name} [{sg.kind}]{desc}")
        if args.task:
            _check_task(name, info, args.model)
    return 0


def _print_shortest(name: str, optimal_steps_range: Any) -> None:
    """The shortest solution of a maze every sub-goal of which can be reached, and a max_steps below it."""
    from ..experiments.driver import max_steps_below_solution

    try:
        low, high = optimal_steps_range(name)
    except RuntimeError:    # the search for it passed its cap of states (a large maze with drop, say)
        print("    reachability: the goal and every sub-goal can be reached; the shortest solution has too many "
              "states to find exactly")
        return
    shortest = f"{low} steps" if low == high else f"{low}-{high} steps, by the start {_drawn(name)}"
    print(f"    reachability: the goal and every sub-goal can be reached; shortest solution {shortest}")
    short = max_steps_below_solution(name)
    if short:
        print(f"    reachability: WARNING: {short}")


def _drawn(name: str) -> str:
    """What a maze draws at random at each reset: its start cell, its start direction, or both."""
    from ..envs import get_task
    from ..envs.minigrid.layout import load_maze_spec

    opts = load_maze_spec(get_task(name).catalogue).options
    what = [w for w, drawn in (("cell", opts.start == "room"), ("direction", opts.start_dir == "random")) if drawn]
    return f"{' and '.join(what)} (drawn at random each episode)"


def _check_task(name: str, info: Any, model: str | None) -> None:
    """What `hubsgo train` checks before a run, without training: the env's own checks (those of
    `hubsgo check-env`, which builds it as this does), a maze's reachability and optimum, and the
    critic spec the run would use."""
    from ..envs import make
    from ..envs.check import scene_warnings
    from ..experiments.run import RunConfig, resolve

    from ..envs.minigrid.registered import is_registered

    env = make(name)           # refuses a bad option, kind or argument, as `hubsgo check-env` does
    try:
        for warning in scene_warnings(env):
            print(f"    scene: WARNING: {warning}")
    finally:
        env.close()

    if info.family == "minigrid" and not is_registered(info.catalogue):
        from ..envs.minigrid.bfs import check_reachable, optimal_steps_range

        never = check_reachable(name)       # a goal no sequence reaches: SpecError
        if never is None:
            print("    reachability: too many states to check exactly; a coarser check over cells found nothing wrong")
        elif never:
            print(f"    reachability: WARNING: no reachable state achieves {', '.join(never)}")
        else:
            _print_shortest(name, optimal_steps_range)
    if info.family == "robosuite":
        from ..experiments.resolve import horizon_below_option

        with contextlib.redirect_stderr(io.StringIO()):     # the budget note comes with the critic spec's lines
            short = horizon_below_option(resolve(RunConfig(task=name, agent="hdqn")))
        if short:
            print(f"    horizon: WARNING: {short}")
    from ..specs import list_model_specs

    if model is None and f"{info.name}-specific" not in list_model_specs():
        print("    critic spec: none built in for this task; check yours with --model SPEC")
        return
    from ..experiments.run import note_unlinked_goals, warn_goals_left_out

    from ..experiments.resolve import BUDGET_NOTE

    notes = io.StringIO()
    with contextlib.redirect_stderr(notes):     # train's note on the budget it would take is a line of the listing
        resolved = resolve(RunConfig(task=name, agent="hubsgo", model=model))
    for line in notes.getvalue().splitlines():
        if line.startswith(BUDGET_NOTE):
            print(f"    budget: {line[len(BUDGET_NOTE):]} (train's default; --steps sets another)")
        else:
            print(line, file=sys.stderr)
    spec = resolved["model_spec"]
    left = resolved.get("subgoals")
    n_edges = len(spec["edges"])
    print(f"    critic spec {resolved['model']!r}: {len(spec['subgoals'])} sub-goals"
          + (f" (a subset: {', '.join(left)})" if left else "") + f", {n_edges} edge{'s' * (n_edges != 1)}, prior "
          f"{spec['prior']['name']}, likelihood {spec['likelihood']['name']}: valid for this task")
    warn_goals_left_out(resolved["model"], resolved["task_ref"], left)      # as `hubsgo train` says them
    note_unlinked_goals(resolved)


def cmd_check_env(args: argparse.Namespace) -> int:
    """``hubsgo check-env ENV``: :func:`hubsgo_ppl.envs.check.check_env` on a task, a catalogue or a
    registered Gymnasium id; prints what is missing, one line each, then the optional parts."""
    from ..envs import _GYM_ID, UnknownTaskError, make
    from ..envs.check import check_env, env_notes, scene_warnings
    from ..experiments.run import RunError

    if args.steps < 1:
        raise RunError(f"--steps must be a positive number of steps, got {args.steps}")
    route = None
    try:
        env = make(args.env)
    except UnknownTaskError as unknown:
        if not _GYM_ID.fullmatch(args.env):
            raise
        env = _gym_env(args.env, unknown)
        route = _catalogue_route(env)
    try:
        problems = check_env(env, steps=args.steps, seed=args.seed)
        notes = env_notes(env) if not problems else []
        warnings = scene_warnings(env, args.seed) if not problems else []
        maze = _maze_warnings(env) if not problems else []
    finally:
        env.close()
    if route:       # a bare Gymnasium id: the catalogue that trains it
        notes.append(route)
    for problem in problems:
        print(f"missing: {problem}")
    for note in notes:
        print(f"note: {note}")
    for warning in warnings + maze:
        print(f"warning: {warning}")
    if not problems:
        count = f"{len(warnings)} warning{'s' * (len(warnings) != 1)}"
        but = f"; but its scene cannot be solved as built ({count} above)" if warnings else ""
        but += "; but see the reachability warning above" if maze else ""
        print(f"{args.env}: meets the sub-goal contract ({args.steps} steps, seed {args.seed}){but}")
    return 1 if problems or warnings or maze else 0


def _maze_warnings(env: Any) -> list[str]:
    """What makes a drawn maze unsolvable or a sub-goal unreachable, as `hubsgo tasks` and `train` check it."""
    spec = getattr(env.unwrapped, "spec_maze", None)
    if spec is None:
        return []
    from ..envs.minigrid.bfs import check_reachable
    from ..specs import SpecError

    try:
        never = check_reachable(spec)
    except SpecError as err:
        return [str(err)]
    return [f"no state the agent can reach achieves {', '.join(never)}"] if never else []


def _gym_env(env_id: str, unknown: Exception) -> Any:
    """The env of a Gymnasium id (MiniGrid's and BabyAI's registered first); an id that is not
    registered is one line naming the closest registered ones."""
    import difflib

    import gymnasium as gym

    from ..experiments.run import RunError

    try:
        import minigrid  # noqa: F401 - registers its ids on import, as a catalogue's gym_id does
    except ImportError:
        pass
    if env_id not in gym.registry:
        if ":" in env_id:                   # "my_pkg:MyEnv-v0": gymnasium imports my_pkg, then looks again
            try:
                return gym.make(env_id)
            except gym.error.Error:
                pass
        if str(unknown).startswith(f"{env_id!r} is the Gymnasium id of task"):
            raise unknown
        near = difflib.get_close_matches(env_id, list(gym.registry), n=3, cutoff=0.6)
        raise RunError(f"{env_id!r} is not a registered Gymnasium id"
                       + (f" (close: {', '.join(near)})" if near else "")
                       + "; pass a built-in task, a catalogue .yaml, or a registered id (import the package "
                         "that registers it with the id's module prefix, my_pkg:MyEnv-v0)")
    return gym.make(env_id)


def _catalogue_route(env: Any) -> str:
    """How to train an environment given by its Gymnasium id: a catalogue that names it and lists its
    sub-goals (MiniGrid's family for a MiniGrid env, the gym family for any other with discrete actions)."""
    import gymnasium as gym

    try:
        from minigrid.minigrid_env import MiniGridEnv
    except ImportError:
        MiniGridEnv = ()
    if isinstance(env.unwrapped, MiniGridEnv):
        from ..envs.minigrid.draft import draft_catalogue, draft_text
        from ..envs.minigrid.registered import PROBE_RESETS

        gym_id = env.spec.id if env.spec is not None else None
        route = ("a MiniGrid environment: to train on it, write a catalogue with family: minigrid and "
                 "options.gym_id naming it, and list its sub-goals (docs/minigrid.md); `hubsgo check-env` that "
                 "catalogue checks it with the sub-goals")
        if gym_id is None:
            return route
        draft = draft_catalogue(gym_id)
        task = draft["task"]
        return (f"{route}. A draft from its {PROBE_RESETS} seeded layouts (an object, door or goal they have, and "
                f"the actions these need) to save as {task}.yaml, edit, and train with --model your spec (your signed "
                f"edges); trained with --graph independent instead, `hubsgo review RUN` suggests the edges its "
                f"successes support:\n\n{draft_text(draft)}")
    if not isinstance(env.action_space, gym.spaces.Discrete):
        return (f"its actions are {type(env.action_space).__name__}, and a Gymnasium environment of your own trains "
                "on Discrete actions only (docs/own_env.md); the arm tasks' continuous control is the robosuite "
                "family's (docs/arms.md)")
    return ("to train on it as it is, write a catalogue with family: gym and options.gym_id naming it, its "
            "sub-goals given as predicates (docs/own_env.md, \"The catalogue, without Python\"): that family "
            "flattens the observation and reports the sub-goals itself, so nothing listed above needs writing; "
            "`hubsgo check-env` that catalogue checks it with the sub-goals")
