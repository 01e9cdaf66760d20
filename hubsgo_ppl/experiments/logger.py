"""One logger with swappable outputs (SB3 style): ``record(key, value)`` then ``dump(step)``.

Tags are namespaced CleanRL-style (``charts/episodic_return``, ``critic/loss``). Outputs: a CSV file
with one row per dump (``metrics.csv``: one row per episode) and TensorBoard events.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any, Protocol

from .io import write_text

__all__ = ["Logger", "CSVOutput", "TensorBoardOutput", "read_csv_rows"]


class Output(Protocol):
    def write(self, values: dict[str, Any], step: int) -> None: ...

    def close(self) -> None: ...


class CSVOutput:
    """Appends rows; new keys after the first row are added by rewriting the file atomically (rare)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.fields: list[str] = []
        if self.path.exists() and self.path.stat().st_size > 0:
            with self.path.open(newline="") as fh:
                self.fields = next(csv.reader(fh), [])

    def write(self, values: dict[str, Any], step: int) -> None:
        new = [k for k in values if k not in self.fields]
        if new:
            rows = read_csv_rows(self.path) if self.fields else []
            self.fields += new
            buf = io.StringIO(newline="")
            w = csv.DictWriter(buf, fieldnames=self.fields)
            w.writeheader()
            w.writerows(rows)
            write_text(self.path, buf.getvalue())    # a kill mid-rewrite must not lose the earlier rows
        with self.path.open("a", newline="") as fh:
            csv.DictWriter(fh, fieldnames=self.fields).writerow(values)

    def close(self) -> None:
        return None


class TensorBoardOutput:
    """Scalars to TensorBoard. ``purge_step`` (on resume): TensorBoard hides events logged at or after
    that step by an earlier, interrupted writer, so a resumed run shows each step once."""

    def __init__(self, log_dir: str | Path, purge_step: int | None = None):
        from torch.utils.tensorboard import SummaryWriter

        self.writer = SummaryWriter(log_dir=str(log_dir), purge_step=purge_step)

    def write(self, values: dict[str, Any], step: int) -> None:
        for k, v in values.items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                self.writer.add_scalar(k, v, step)

    def close(self) -> None:
        self.writer.flush()
        self.writer.close()


class Logger:
    def __init__(self, outputs: list[Output]):
        self.outputs = outputs
        self.values: dict[str, Any] = {}

    def record(self, key: str, value: Any) -> None:
        self.values[key] = value

    def dump(self, step: int) -> None:
        for out in self.outputs:
            out.write(self.values, step)
        self.values = {}

    def close(self) -> None:
        """Close every output, even if one of them fails (the first failure is raised afterwards)."""
        error: BaseException | None = None
        for out in self.outputs:
            try:
                out.close()
            except Exception as exc:  # noqa: BLE001 - re-raised below, after the others are closed
                error = error or exc
        if error is not None:
            raise error


def read_csv_rows(path: str | Path) -> list[dict[str, str]]:
    path = Path(path)
    if not path.exists():
        return []
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))
