"""Per-episode trace of the HRL loop (a diagnostic, not a benchmark): Ĝt, ε's and the chosen sub-goals.

    .venv/bin/python benchmarks/trace_options.py keydoor --agent hubsgo --seed 3 --steps 17000

Prints one line per training episode: env steps so far, return, length, the high-level and filter ε,
Ĝt as the loop read it at the episode's start (``-`` before the critic's first update, or for h-DQN)
and the first sub-goals the high level chose (initials: ``yk`` = yellow_key). docs/results.md uses it
to show where HUBS-GO's extra timeouts on KeyDoor come from. Extra ``--set`` overrides as for
``hubsgo train``; the run is the same as ``hubsgo train`` with that seed, minus the files.

``--detail 154,280`` also prints those episodes step by step, one line per option: the sub-goal, the
set it was chosen from, then ``x,y`` plus the facing (``>v<^``) and the initial of a carried object
after each env step (MiniGrid tasks only). ``--only-detail`` prints nothing else.
"""

from __future__ import annotations

import argparse

import torch

from hubsgo_ppl.experiments.run import RunConfig, _build, resolve


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("task")
    p.add_argument("--agent", default="hubsgo", choices=["hubsgo", "hdqn"])
    p.add_argument("--model", default=None, help="critic spec name or path (default: TASK-specific)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--steps", type=int, default=None, help="stop after this many env steps (default: budget)")
    p.add_argument("--first", type=int, default=12, help="chosen sub-goals shown per episode")
    p.add_argument("--set", action="append", default=[], help="hyperparameter override")
    p.add_argument("--detail", default="", help="comma-separated episode numbers to print step by step")
    p.add_argument("--only-detail", action="store_true", help="print only the --detail episodes")
    args = p.parse_args()
    detail = {int(x) for x in args.detail.split(",") if x.strip()}
    torch.set_num_threads(1)
    resolved = resolve(RunConfig(task=args.task, agent=args.agent, model=args.model, seed=args.seed,
                                  overrides=args.set))
    _, loop = _build(resolved)
    stop = args.steps or int(resolved["hyper"]["steps"])
    initials = {n: "".join(w[0] for w in n.split("_")) for n in loop.names}
    steps: list[str] = []
    if detail:
        _record_steps(loop, initials, steps)
    while loop.env_steps < stop:
        steps.clear()
        mask = loop.filter.allowed()
        ghat = "-" if mask is None else ",".join(initials[n] for n, m in zip(loop.names, mask) if m)
        st = loop.run_episode(train=True)
        chosen = " ".join(initials[c] for c in st.chosen[: args.first])
        if not args.only_detail:
            print(f"ep {st.episode:5d}  t={st.env_steps:6d}  R={st.ret:.3f}  len={st.length:5d}  "
                  f"eps={st.explore_eps:.2f}  filter={st.filter_eps:.2f}  Ĝt={ghat:<16} | {chosen}", flush=True)
        if st.episode in detail:
            print(f"=== episode {st.episode}: return {st.ret:.3f}, {st.length} steps")
            print("\n".join(steps), flush=True)
        if detail and st.episode >= max(detail) and args.only_detail:
            break


def _record_steps(loop, initials: dict[str, str], out: list[str]) -> None:
    """Wrap the loop's env step and high-level choice so that each option appends one line to ``out``."""
    env = loop.env.unwrapped
    if not hasattr(env, "agent_pos"):
        raise SystemExit("--detail needs a MiniGrid task (the agent's cell and facing)")
    step, select = loop.env.step, loop.high.select

    def traced_step(action):
        result = step(action)
        carried = env.carrying
        out[-1] += f" {env.agent_pos[0]},{env.agent_pos[1]}{'>v<^'[int(env.agent_dir)]}" + (
            "" if carried is None else carried.color[0])
        return result

    def traced_select(obs, allowed, explore):
        g = select(obs, allowed, explore)
        offered = " ".join(initials[n] for n, m in zip(loop.names, allowed) if m)
        out.append(f"  [{initials[loop.names[g]]:>2} from {offered}]")
        return g

    loop.env.step, loop.high.select = traced_step, traced_select


if __name__ == "__main__":
    main()
