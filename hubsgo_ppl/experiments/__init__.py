"""Running experiments: :func:`train` (a driver calling :class:`Callback` objects), :class:`RunConfig`,
evaluation, sweeps, revisions and transfers; :func:`train_env` on a Gymnasium env of one's own.

    from hubsgo_ppl.experiments import Callback, RunConfig, train

    class StopAtFirstSuccess(Callback):
        def on_episode(self, run, stats):
            return not stats.success        # False stops the run (a pause: resume continues it)

    train(RunConfig(task="keydoor", steps=20_000), "runs/kd", callbacks=[StopAtFirstSuccess()])

The names are loaded on first use, so importing a submodule (``experiments.io``) stays light.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["Callback", "CallbackList", "TrainingRun", "ResolvedRun", "RunConfig", "RunError", "train", "train_env"]

_HOMES = {"Callback": "callbacks", "CallbackList": "callbacks", "TrainingRun": "callbacks", "train": "driver",
          "ResolvedRun": "resolved", "RunConfig": "resolved", "RunError": "resolved", "train_env": "own_env"}


def __getattr__(name: str) -> Any:
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
