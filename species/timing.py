"""Stage timings: wall-clock seconds per named stage, in the order the stages first ran. The farm's tree chain and
asset jobs time blocks with it; the reconstruction methods time their steps for their reports."""
from __future__ import annotations

import time
from contextlib import contextmanager

__all__ = ["StageTimer"]


class StageTimer:
    """Seconds per named stage (`seconds`, in the order the stages first ran), timed either of two ways:

    `with timer.stage(name):` around a block; `current` names the stage begun last, so an error can say which
    stage it came from. `timer.lap(name)` where a stage ends: the seconds since the previous lap or block ended,
    or since the timer was made. A stage timed again adds up.
    """

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.current = "start"
        self._mark = time.perf_counter()

    def _add(self, name: str, start: float) -> None:
        self._mark = time.perf_counter()
        self.seconds[name] = self.seconds.get(name, 0.0) + self._mark - start

    @contextmanager
    def stage(self, name: str):
        self.current = name
        start = time.perf_counter()
        try:
            yield
        finally:
            self._add(name, start)

    def lap(self, name: str) -> None:
        self._add(name, self._mark)
