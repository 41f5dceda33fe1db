"""species.timing.StageTimer: blocks and laps share one table of seconds per stage, in the order they first ran."""
from __future__ import annotations

import time

import pytest

from species.timing import StageTimer


def test_a_block_timed_twice_adds_up_and_current_names_the_stage_an_error_left():
    timer = StageTimer()
    for _ in range(2):
        with timer.stage("grow"):
            time.sleep(0.01)
    with pytest.raises(RuntimeError):
        with timer.stage("render"):
            raise RuntimeError("broken")
    assert list(timer.seconds) == ["grow", "render"]
    assert timer.seconds["grow"] >= 0.02 and timer.current == "render"


def test_a_lap_counts_from_the_previous_lap_or_block():
    timer = StageTimer()
    time.sleep(0.01)
    timer.lap("read")
    with timer.stage("fit"):
        time.sleep(0.02)
    timer.lap("write")  # right after the block: next to nothing
    assert list(timer.seconds) == ["read", "fit", "write"]
    assert timer.seconds["read"] >= 0.01 and timer.seconds["fit"] >= 0.02
    assert timer.seconds["write"] < timer.seconds["read"]
