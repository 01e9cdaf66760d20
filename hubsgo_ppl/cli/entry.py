"""``hubsgo``'s entry point: parse the command line, run the command, and say every failure in one line.

The package's modules import only the standard library when they load (each command imports what it
needs when it runs), so that Ctrl-C at any moment after ``main`` is called, start-up included, ends
in one line and exit status 2."""

from __future__ import annotations

import os
import sys
import traceback
from pathlib import Path
from typing import Sequence

from .parser import UsageError, build_parser

__all__ = ["main", "EXTRAS"]

#: optional modules -> the extra of hubsgo-ppl that installs them
EXTRAS = {"robosuite": "robosuite", "mujoco": "robosuite", "ray": "ray"}


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``hubsgo`` with ``argv`` (default: the process's arguments); returns the exit status."""
    try:
        return _run(argv)
    except KeyboardInterrupt:       # Ctrl-C: while importing, building, reading G*, reviewing, ...
        command = _command(sys.argv[1:] if argv is None else list(argv))
        print(f"hubsgo: interrupted (Ctrl-C){f' during `hubsgo {command}`' if command else ''}", file=sys.stderr)
        return 2


def _command(argv: list[str]) -> str | None:
    """The subcommand named in ``argv``, for the line that says where Ctrl-C stopped it."""
    return next((a for a in argv if not a.startswith("-")), None)


def _run(argv: Sequence[str] | None) -> int:
    from ..errors import CheckpointError, ReportError, RunError, SpecError   # an unknown task is a SpecError

    parser = build_parser()
    try:
        args, extra = parser.parse_known_args(argv)
        if extra:
            raise UsageError(f"unrecognized arguments: {' '.join(extra)}; see `hubsgo {args.command} --help`")
    except UsageError as exc:
        print(f"hubsgo: error: {exc}", file=sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except BrokenPipeError:     # the reader went away (`hubsgo ... | head`): stop quietly, as Unix tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())       # no second error when Python flushes stdout at exit
        return 1
    except (SpecError, RunError, CheckpointError, ReportError, FloatingPointError) as exc:
        msg = str(exc).strip().replace("\n", "; ")
        print(f"hubsgo: error: {msg}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as exc:
        module = (exc.name or "").split(".")[0]
        if module not in EXTRAS:
            raise               # not an optional extra: a broken install or a bug, keep the traceback
        what = " ".join(str(a) for a in (args.command, getattr(args, "task", None)) if a)
        print(f"hubsgo: error: `hubsgo {what}` needs {module}, which is not installed; install the "
              f'{EXTRAS[module]} extra: pip install "hubsgo-ppl[{EXTRAS[module]}]"', file=sys.stderr)
        return 2
    except OSError as exc:      # a folder that cannot be written, a full disk: the file and the reason
        where = f"{exc.filename}: " if exc.filename else ""
        if isinstance(exc, NotADirectoryError) or (isinstance(exc, FileExistsError) and exc.filename and
                                                   Path(exc.filename).is_file()):   # mkdir of a file, or through one
            print(f"hubsgo: error: {where}a file where a folder goes, or in its path; choose another folder",
                  file=sys.stderr)
            return 2
        print(f"hubsgo: error: {where}{exc.strerror or exc}; check the folder's permissions and free space",
              file=sys.stderr)
        return 2
    except Exception as exc:    # no check of ours names this: one line, and the traceback on request
        if os.environ.get("HUBSGO_TRACEBACK"):
            raise
        frame = traceback.extract_tb(exc.__traceback__)[-1]
        msg = " ".join(str(exc).split())[:300]
        print(f"hubsgo: error: unexpected {type(exc).__name__}: {msg} (in {Path(frame.filename).name}, line "
              f"{frame.lineno}); HUBSGO_TRACEBACK=1 shows the traceback", file=sys.stderr)
        return 1
