"""Per-episode trace of the HRL loop (a diagnostic, not a benchmark): Ĝt, ε's and the chosen sub-goals.

    .venv/bin/python benchmarks/trace_options.py keydoor --agent hubsgo --seed 3 --steps 17000

Prints one line per training episode: env steps so far, return, length, the high-level and filter ε,
Ĝt as the loop read it at the episode's start (``-`` before the critic's first update, or for h-DQN)
and the first sub-goals the high level chose (initials: ``yk`` = yellow_key). docs/results.md uses it
to show where HUBS-GO's extra timeouts on KeyDoor come from. Extra ``--set`` overrides as for
``hubsgo train``; the run is the same as ``hubsgo train`` with that seed, minus the files.
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
    args = p.parse_args()
    torch.set_num_threads(1)
    resolved = resolve(RunConfig(task=args.task, agent=args.agent, model=args.model, seed=args.seed,
                                  overrides=args.set))
    _, loop = _build(resolved)
    stop = args.steps or int(resolved["hyper"]["steps"])
    initials = {n: "".join(w[0] for w in n.split("_")) for n in loop.names}
    while loop.env_steps < stop:
        mask = loop.filter.allowed()
        ghat = "-" if mask is None else ",".join(initials[n] for n, m in zip(loop.names, mask) if m)
        st = loop.run_episode(train=True)
        chosen = " ".join(initials[c] for c in st.chosen[: args.first])
        print(f"ep {st.episode:5d}  t={st.env_steps:6d}  R={st.ret:.3f}  len={st.length:5d}  "
              f"eps={st.explore_eps:.2f}  filter={st.filter_eps:.2f}  Ĝt={ghat:<16} | {chosen}", flush=True)


if __name__ == "__main__":
    main()
