"""Stage timings for the reconstruction methods' reports: seconds per named stage, in the order they ran."""
from __future__ import annotations

import time

__all__ = ["StageTimer"]


class StageTimer:
    """`lap(name)` records the seconds since the previous lap (or since the timer was made) under `name`."""

    def __init__(self) -> None:
        self.timings: dict[str, float] = {}
        self._clock = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.timings[name] = now - self._clock
        self._clock = now
