"""Linear schedules for the two ε's of the loop (exploration ε decays; the HUBS-GO filter ε rises, Sec. 3.4)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["LinearSchedule"]


@dataclass(frozen=True)
class LinearSchedule:
    """``start`` at progress 0, ``end`` from progress ``fraction`` on (progress = env steps / budget)."""

    start: float
    end: float
    fraction: float

    def __call__(self, progress: float) -> float:
        if self.fraction <= 0:
            return self.end
        t = min(max(progress / self.fraction, 0.0), 1.0)
        return self.start + t * (self.end - self.start)
