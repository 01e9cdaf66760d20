"""The run folder lock: one process at a time writes a run folder.

``train`` (new or ``--resume``) holds an exclusive ``flock`` on ``RUN/.lock`` from before it reads
the folder until it returns; a second process that tries is refused in one line instead of
interleaving its rows, config and checkpoint with the first's. The kernel drops the lock when the
process ends, however it ends (``kill -9`` included), so a killed run never leaves a stale lock.
The lock file is empty and is removed on release (a process that opened it meanwhile sees that the
file it locked is no longer the one at the path, and tries again).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
from pathlib import Path
from typing import Iterator

from .resolved import RunError

__all__ = ["LOCK_FILE", "run_folder_lock"]

LOCK_FILE = ".lock"


def _unwritable(out: Path, exc: OSError, flag: str) -> RunError:
    where = f"{flag} {out}" if flag else f"{out}"
    return RunError(f"{where}: cannot write there ({exc.strerror}); "
                    + ("choose a writable folder" if flag else "a run is written where it lies; make it writable"))


def _open_lock(path: Path, flag: str) -> int:
    """Open (creating, mode 0666 & ~umask) the lock file without following a symlink."""
    try:
        return os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise RunError(f"{path}: a symbolic link where the run's lock file goes; remove it") from None
        raise _unwritable(path.parent, exc, flag) from None


@contextlib.contextmanager
def run_folder_lock(out: str | Path, flag: str = "--out") -> Iterator[bool]:
    """Hold the lock of run folder ``out`` (created if missing) for the block; yields whether the folder
    was created. A folder created here that is empty when the block ends is removed, so a run that
    could not start leaves no folder of its own. ``flag`` is the option that named the folder in the
    messages ("" for a command that writes the run where it lies, as ``revise``)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise RunError(f"--out {out}: a file, not a folder; choose a folder for the run")
    if out.is_symlink():
        raise RunError(f"--out {out}: a symbolic link; give the folder it points to, or another folder")
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _unwritable(out, exc, flag) from None
    path = out / LOCK_FILE
    while True:
        fd = _open_lock(path, flag)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise RunError(f"{out}: another process is writing this run folder (it holds {path}); wait for it "
                               "to end" + (f", or choose another {flag}" if flag else "")) from None
            raise
        try:        # the file locked is still the one at the path (not one unlinked meanwhile)
            same = os.path.samestat(os.fstat(fd), os.stat(path, follow_symlinks=False))
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        yield created
    finally:
        try:            # removed while still locked; a process that opened it meanwhile sees it went, above
            path.unlink()
            if created and not any(out.iterdir()):
                out.rmdir()
        except OSError:
            pass
        os.close(fd)        # releases the lock
