"""``hubsgo``: train, evaluate and inspect HUBS-GO runs.

    hubsgo train TASK [--agent hubsgo|hdqn|ddqn|...] [--model SPEC] [--steps N] [--seed S] [--out DIR] [--resume]
                      [--stop-at STEP] [--init-from RUN [--transfer critic,high,low] [--restart-schedules]]
    hubsgo revise RUN_DIR --model NEW_SPEC [--steps TOTAL] [--stop-at STEP] [--no-train]
    hubsgo evaluate RUN_DIR [--episodes K]
    hubsgo subgoals RUN_DIR
    hubsgo tasks [TASK_OR_CATALOGUE ...] [--model SPEC]
    hubsgo diagnose RUN_DIR [--chains 4]
    hubsgo sweep SWEEP.yaml [--backend local|ray] [--workers K] [--variants NAME ...] [--tasks NAME ...]
    hubsgo report SWEEP_DIR
    hubsgo review RUN_DIR [--threshold 0.2] [--out DIR] [--no-gif]
    hubsgo render RUN_DIR [--out FILE.gif] [--seed N]

The package: ``parser`` (the command line and its help), ``entry`` (``main``: run a command, every
failure in one line), and the commands by what they do: ``training`` (train, revise), ``readouts``
(evaluate, subgoals, diagnose, review, render), ``tasks``, ``sweeps`` (sweep, report); ``show``
prints results.
"""

from __future__ import annotations

from .entry import main
from .parser import build_parser

__all__ = ["main", "build_parser"]
