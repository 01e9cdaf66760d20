"""The run's logger: Stable-Baselines3's :class:`~stable_baselines3.common.logger.Logger` (``record(key,
value)`` then ``dump(step)``) with two outputs, a CSV file and TensorBoard.

Tags are the ``metrics.csv`` columns: the episode's own plain (``return``, ``success``, ``length``), the
learners' namespaced by part (``critic/loss``, ``high/td_loss``, ``low/td_loss``). Outputs: ``metrics.csv``
(one row per dump, i.e. per episode) and TensorBoard events.

What comes from SB3 and what does not:

* :class:`Logger` is SB3's, with one change: :meth:`Logger.close` closes every output even if one of
  them fails (SB3's stops at the first failure and leaves the others open). ``Logger.outputs`` is
  SB3's ``output_formats`` list.
* :class:`TensorBoardOutput` is SB3's ``TensorBoardOutputFormat`` with a ``purge_step``: on resume,
  TensorBoard hides events logged at or after that step by an earlier, interrupted writer, so a resumed
  run shows each step once. (SB3 builds its ``SummaryWriter`` without one, and a writer opens its
  events file when built, so the writer is built here instead of by SB3's ``__init__``.)
* :class:`CSVOutput` is our own :class:`~stable_baselines3.common.logger.KVWriter`. SB3's
  ``CSVOutputFormat`` cannot keep what the run harness relies on: it opens its file with mode ``w+``,
  so reopening a run's ``metrics.csv`` on ``--resume`` would erase the rows kept up to the checkpoint
  (the harness first truncates them to the checkpoint, then appends); when a new column appears it
  rewrites the header and every row in place, so a kill mid-rewrite loses rows (ours writes a new file
  and renames it over the old one); and it adds new columns in set order, so the column order of two
  identical runs can differ (ours keeps first-seen order, which is what makes an interrupted and
  resumed run's files equal to an uninterrupted run's).
"""

from __future__ import annotations

import csv
import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from stable_baselines3.common.logger import KVWriter, TensorBoardOutputFormat, filter_excluded_keys
from stable_baselines3.common.logger import Logger as SB3Logger

from .io import RunFileError, append_text, damaged_log, write_text

__all__ = ["Logger", "CSVOutput", "TensorBoardOutput", "read_csv_rows"]


class CSVOutput(KVWriter):
    """Appends one row per write; new keys after the first row are added by rewriting the file atomically
    (rare). An existing file is appended to under its own header.

    As an SB3 output it is called ``write(values, excluded, step)``; it can also be written directly as
    ``write(values, step)`` (the critic's history). ``step`` is not a column: pass it as a value if wanted.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.fields: list[str] = []
        if self.path.exists() and self.path.stat().st_size > 0:
            try:
                with self.path.open(newline="", encoding="utf-8") as fh:
                    self.fields = next(csv.reader(fh), [])
            except (UnicodeDecodeError, csv.Error) as exc:
                raise damaged_log(self.path, exc) from None

    def write(self, key_values: dict[str, Any], key_excluded: Mapping[str, Any] | int | None = None,
              step: int = 0) -> None:
        if isinstance(key_excluded, Mapping):
            key_values = filter_excluded_keys(key_values, dict(key_excluded), "csv")
        new = [k for k in key_values if k not in self.fields]
        if new:
            rows = read_csv_rows(self.path) if self.fields else []
            # the run's wall time stays the last column, as in a log whose keys all came with its first row
            tail = self.fields[-1:] if self.fields[-1:] == ["wall_time"] else []
            self.fields = self.fields[:len(self.fields) - len(tail)] + new + tail
            buf = io.StringIO(newline="")
            w = csv.DictWriter(buf, fieldnames=self.fields)
            w.writeheader()
            w.writerows(rows)
            write_text(self.path, buf.getvalue())    # a kill mid-rewrite must not lose the earlier rows
        buf = io.StringIO(newline="")
        csv.DictWriter(buf, fieldnames=self.fields).writerow(key_values)
        append_text(self.path, buf.getvalue())

    def close(self) -> None:
        return None


class TensorBoardOutput(TensorBoardOutputFormat):
    """SB3's TensorBoard output with ``purge_step`` (on resume: events of an earlier, interrupted writer
    at or after that step are hidden)."""

    def __init__(self, log_dir: str | Path, purge_step: int | None = None):
        # not super().__init__: it would open a second events file, without purge_step
        from torch.utils.tensorboard import SummaryWriter

        if Path(log_dir).exists() and not Path(log_dir).is_dir():
            raise RunFileError(f"{log_dir}: a file where the TensorBoard folder goes; move it away")

        self.writer = SummaryWriter(log_dir=str(log_dir), purge_step=purge_step)
        self._is_closed = False


class Logger(SB3Logger):
    """SB3's logger over ``outputs`` (each an SB3 ``KVWriter``), without a log folder of its own."""

    def __init__(self, outputs: list[KVWriter]):
        super().__init__(folder=None, output_formats=outputs)

    @property
    def outputs(self) -> list[KVWriter]:
        return self.output_formats

    def close(self) -> None:
        """Close every output, even if one of them fails (the first failure is raised afterwards)."""
        error: BaseException | None = None
        for out in self.output_formats:
            try:
                out.close()
            except Exception as exc:  # noqa: BLE001 - re-raised below, after the others are closed
                error = error or exc
        if error is not None:
            raise error


def read_csv_rows(path: str | Path, required: Sequence[str] = ()) -> list[dict[str, str]]:
    """The rows of a CSV log (none if it is missing); a file that is not one, or whose header lacks a
    ``required`` column, is refused in one line (:class:`RunFileError`)."""
    path = Path(path)
    if not path.exists():
        return []
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            rows = list(reader)
            header = reader.fieldnames or []
    except (UnicodeDecodeError, csv.Error) as exc:
        raise RunFileError(f"{path}: damaged, not a CSV log ({exc})") from None
    missing = [c for c in required if c not in header]
    if rows and missing:
        raise RunFileError(f"{path}: damaged, its header lacks {', '.join(missing)}")
    return rows
