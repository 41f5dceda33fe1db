"""Douglas-Peucker keys of many polylines at once: known answers, agreement with the recursive algorithm, nesting."""
from __future__ import annotations

import numpy as np
import pytest

from species.geometry.polyline_simplify import simplification_keys


def _recursive_kept(points: np.ndarray, radius: np.ndarray, tolerance: float) -> set[int]:
    """The textbook recursive Douglas-Peucker (same error: distance to the chord plus radius bulge)."""
    kept = {0, len(points) - 1}

    def split(lo: int, hi: int) -> None:
        if hi - lo < 2:
            return
        a, b = points[lo], points[hi]
        chord = b - a
        inner = points[lo + 1:hi]
        t = np.clip((inner - a) @ chord / max(chord @ chord, 1e-300), 0.0, 1.0)
        error = (np.linalg.norm(inner - (a + t[:, None] * chord), axis=1)
                 + np.abs(radius[lo + 1:hi] - (radius[lo] + t * (radius[hi] - radius[lo]))))
        worst = int(np.argmax(error))
        if error[worst] > tolerance:
            kept.add(lo + 1 + worst)
            split(lo, lo + 1 + worst)
            split(lo + 1 + worst, hi)

    split(0, len(points) - 1)
    return kept


def test_a_straight_even_line_needs_only_its_ends():
    points = np.stack([np.linspace(0, 1, 7), np.zeros(7), np.zeros(7)], axis=1)
    keys = simplification_keys(points, np.full(7, 0.1), np.array([0, 7]))
    assert np.isinf(keys[[0, 6]]).all() and np.all(keys[1:6] == 0.0)


def test_the_apex_of_a_bend_has_its_distance_to_the_chord_as_key():
    points = np.array([[0.0, 0, 0], [1.0, 0.5, 0], [2.0, 0, 0]])
    keys = simplification_keys(points, np.zeros(3), np.array([0, 3]))
    assert keys[1] == pytest.approx(0.5)


def test_a_radius_bulge_counts_as_error():
    points = np.stack([np.linspace(0, 2, 3), np.zeros(3), np.zeros(3)], axis=1)
    keys = simplification_keys(points, np.array([0.1, 0.3, 0.1]), np.array([0, 3]))
    assert keys[1] == pytest.approx(0.2)


@pytest.mark.parametrize("seed", range(4))
def test_keys_keep_exactly_what_recursive_douglas_peucker_keeps_at_every_tolerance(seed):
    rng = np.random.default_rng(seed)
    sizes = rng.integers(2, 30, 6)
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    points = np.cumsum(rng.normal(size=(offsets[-1], 3)), axis=0)
    radius = rng.uniform(0.05, 0.2, offsets[-1])
    keys = simplification_keys(points, radius, offsets)
    for tolerance in (0.05, 0.3, 1.0, 3.0):
        for lo, hi in zip(offsets[:-1], offsets[1:]):
            expected = _recursive_kept(points[lo:hi], radius[lo:hi], tolerance)
            assert set(np.flatnonzero(keys[lo:hi] > tolerance)) == expected


def test_kept_sets_are_nested_as_the_tolerance_grows():
    rng = np.random.default_rng(5)
    points = np.cumsum(rng.normal(size=(200, 3)), axis=0)
    keys = simplification_keys(points, np.zeros(200), np.array([0, 80, 200]))
    coarse, fine = keys > 2.0, keys > 0.5
    assert coarse.sum() < fine.sum() and not (coarse & ~fine).any()
