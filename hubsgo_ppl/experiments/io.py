"""Atomic file writes and checkpoint loading.

Every file is written to a temporary file in the same folder, fsynced, then ``os.replace``d over the
target, so a reader (or a resumed run) sees either the old file or the new one, never half of one.
The temporary file is created with mode 0666 filtered by the process umask, exactly like a plain
``open(path, "w")``, so the outputs of a run are readable by group and others under umask 022.

This module holds the package's one atomic-write implementation: :func:`atomic_path` (a temporary
path for writers that need a file name, e.g. ``to_netcdf``) and :func:`atomic_write` (a file handle).
Writes never follow a symbolic link: an atomic write replaces the link itself, and :func:`append_text`
(the CSV logs) refuses one.

Checkpoints load with ``torch.load(..., weights_only=True)``: tensors, plain Python data and numpy
arrays only. A checkpoint that carries any other pickled object (a function, a class) is refused.
"""

from __future__ import annotations

import contextlib
import csv
import errno
import io
import json
import os
import secrets
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch
import yaml

from ..errors import CheckpointError

__all__ = ["atomic_path", "atomic_write", "append_text", "write_text", "write_json", "write_yaml", "save_torch",
           "load_checkpoint", "checkpoint_globals", "is_temp_file", "truncate_csv", "CheckpointError"]

_TMP_SUFFIX = ".tmp"


class RunFileError(CheckpointError):
    """Another file of a run directory (a CSV log, a JSON table) is damaged; the message names it."""


def damaged_log(path: Path, exc: Exception) -> RunFileError:
    """The error for a CSV log a run appends to that cannot be read as one."""
    return RunFileError(f"{path}: damaged, not a CSV log ({exc}); move it out of the run directory to go on "
                        "without its rows")


def _create_temp(path: Path, suffix: str) -> Path:
    """A new, empty file next to ``path``, created like ``open()`` would (mode 0666 & ~umask)."""
    for _ in range(100):
        tmp = path.parent / f".{path.name}.{secrets.token_hex(4)}{_TMP_SUFFIX}{suffix}"
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FileExistsError(errno.EEXIST, "no free temporary file name", str(path.parent))


def is_temp_file(path: str | Path, target: str | None = None) -> bool:
    """Whether ``path`` is a temporary file left by an interrupted atomic write (of ``target`` if given)."""
    name = Path(path).name
    prefix = f".{target}." if target is not None else "."
    return name.startswith(prefix) and _TMP_SUFFIX in name[len(prefix):]


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | Path, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path next to ``path``; when the block ends without an exception, the file
    written there is fsynced and replaces ``path``. On an exception ``path`` is left as it was and
    the temporary file is removed. ``suffix`` ends the temporary name (for writers that pick a format
    by extension). Parent folders are created."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        tmp = _create_temp(path, suffix)
    except OSError as exc:      # name the file the user asked for, not the temporary one
        raise OSError(exc.errno, exc.strerror, str(path)) from None
    try:
        yield tmp
        fd = os.open(tmp, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def atomic_write(path: str | Path, writer: Callable[[Any], None], mode: str = "wb", suffix: str = "") -> Path:
    """Write ``path`` atomically through ``writer(file_handle)``; ``mode`` is ``"wb"`` or ``"w"``;
    ``suffix`` ends the temporary file's name (:func:`atomic_path`)."""
    with atomic_path(path, suffix=suffix) as tmp:
        with open(tmp, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""})) as fh:
            writer(fh)
    return Path(path)


def append_text(path: str | Path, text: str) -> None:
    """Append ``text`` to ``path`` (created like ``open()`` would); a symbolic link there is refused
    (:class:`RunFileError`), never written through."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise RunFileError(f"{path}: a symbolic link; a run's logs are written only in its own folder, never "
                               "through a link; move the link away") from None
        raise
    with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
        fh.write(text)


def write_text(path: str | Path, text: str) -> Path:
    return atomic_write(path, lambda fh: fh.write(text), mode="w")


def write_json(path: str | Path, obj: Any) -> Path:
    return write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")


def write_yaml(path: str | Path, obj: Any) -> Path:
    return write_text(path, yaml.safe_dump(obj, sort_keys=False))


def truncate_csv(path: str | Path, column: str, below: int) -> None:
    """Cut a CSV log back to its rows whose ``column`` is ``< below`` (header and column order kept);
    later rows and a partly written last row go, atomically. A file without that column in its header
    (cut short while it was first written) is removed. A missing file is left missing."""
    path = Path(path)
    if not path.exists():
        return
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            table = list(csv.reader(fh))
    except (UnicodeDecodeError, csv.Error) as exc:
        raise damaged_log(path, exc) from None
    header, rows = (table[0], table[1:]) if table else ([], [])
    if column not in header:
        path.unlink()
        return
    col = header.index(column)

    def keep(row: list[str]) -> bool:
        try:
            return len(row) == len(header) and int(float(row[col])) < below
        except ValueError:
            return False

    kept = [r for r in rows if keep(r)]
    if len(kept) != len(rows):
        buf = io.StringIO(newline="")
        csv.writer(buf).writerows([header, *kept])     # the line ending csv.DictWriter appends with
        write_text(path, buf.getvalue())


def save_torch(path: str | Path, obj: Any) -> Path:
    return atomic_write(path, lambda fh: torch.save(obj, fh))


def _numpy_globals() -> list[Any]:
    """What pickled numpy arrays and scalars need: the array rebuilder, ndarray, dtype and its classes."""
    core = getattr(np, "_core", None)
    multiarray = getattr(core, "multiarray", None) if core is not None else None
    if multiarray is None or not hasattr(multiarray, "_reconstruct"):
        multiarray = np.core.multiarray
    kinds = ("bool", "int8", "int16", "int32", "int64", "uint8", "uint16", "uint32", "uint64",
             "float16", "float32", "float64", "complex64", "complex128")
    return [multiarray._reconstruct, multiarray.scalar, np.ndarray, np.dtype,
            *{type(np.dtype(k)) for k in kinds}]


def checkpoint_globals(path: str | Path) -> list[str]:
    """Names of the pickled globals in ``path`` that a weights-only load refuses (empty if none)."""
    allowed = {f"{g.__module__}.{g.__qualname__}" for g in _numpy_globals()}
    allowed |= {f"{g.__module__}.{g.__name__}" for g in _numpy_globals()}
    try:
        found = torch.serialization.get_unsafe_globals_in_checkpoint(str(path))
    except Exception:   # not a zip checkpoint: nothing to name
        return []
    return sorted(g for g in found if g not in allowed)


def _first_sentence(text: str, limit: int = 120) -> str:
    """The first sentence of an exception's first line, cut at a word (with "...") past ``limit`` characters."""
    first = text.strip().splitlines()[0] if text.strip() else ""
    end = first.find(". ")
    if end >= 0:
        first = first[:end + 1]
    if len(first) > limit:
        first = first[:limit].rsplit(" ", 1)[0] + "..."
    return first


def load_checkpoint(path: str | Path, mmap: bool = False) -> dict[str, Any]:
    """Load a checkpoint written by :func:`save_torch` (state_dicts, plain data and numpy arrays only)."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no checkpoint here; train first, or drop --resume to start anew")
    try:
        with warnings.catch_warnings(), torch.serialization.safe_globals(_numpy_globals()):
            warnings.simplefilter("ignore")
            obj = torch.load(path, map_location="cpu", weights_only=True, mmap=mmap)
    except Exception as exc:  # torch raises several types for truncated/garbled/unsafe files
        unsafe = checkpoint_globals(path) if "weights only" in str(exc).lower() else []
        if unsafe:
            raise CheckpointError(
                f"{path}: refusing to load: the checkpoint holds pickled code or objects "
                f"({', '.join(unsafe[:5])}), not only tensors and plain data; "
                "use a checkpoint written by `hubsgo train`") from None
        raise CheckpointError(
            f"{path}: checkpoint is corrupt or unreadable ({type(exc).__name__}: {_first_sentence(str(exc))}); "
            "start a new run with another --out") from None
    if not isinstance(obj, dict) or "format" not in obj:
        raise CheckpointError(f"{path}: not a hubsgo checkpoint (no 'format' key); "
                              "point at a run directory written by `hubsgo train`")
    return obj
