"""The errors that ``hubsgo`` reports in one line (``hubsgo: error: ...``, exit status 2), without a
traceback: each message names the cause and the fix. This module imports nothing, so that the command
line can catch them before it loads what a command needs.

Each is also importable from the module that raises it (``specs``, ``experiments.resolved``,
``experiments.io``, ``experiments.report``).
"""

from __future__ import annotations

__all__ = ["SpecError", "RunError", "RunInterrupted", "CheckpointError", "ReportError"]


class SpecError(ValueError):
    """A spec (model, task catalogue, sweep) is malformed. The message says where and how to fix it."""


class RunError(RuntimeError):
    """A run cannot start or continue; the message names the cause and the fix."""


class RunInterrupted(RunError):
    """A run stopped by Ctrl-C (or by its worker's parent dying); the message says how to continue it.
    Not a refusal of its folder: whoever started it must not start it again on its own."""


class CheckpointError(RuntimeError):
    """A checkpoint is missing, unreadable or unsafe; the message says which file and what to do."""


class ReportError(Exception):
    """A folder that does not hold what `hubsgo sweep` writes; the message says what is wrong."""
