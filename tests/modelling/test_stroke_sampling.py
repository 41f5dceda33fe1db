"""Specification of hand-drawn strokes (farm.modelling.strokes): sparse sampling, Hermite joining, closed or open.

Named apart from tests/renderers/test_strokes.py (pytest needs unique basenames in this suite)."""
from __future__ import annotations

import numpy as np
import pytest

from farm.modelling.strokes import (arc_lengths, MIN_RING_POINTS, resample_polyline, sample_stroke, stroke_is_closed,
                                    StrokeError)


def _circle(count: int = 200, radius: float = 1.0, jitter: float = 0.0, seed: int = 0) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, count)
    points = np.stack([radius * np.cos(t), radius * np.sin(t), np.full(count, 1.5)], axis=1)
    return points + np.random.default_rng(seed).normal(0, jitter, points.shape)


def test_a_drawn_loop_comes_back_a_smooth_evenly_spaced_ring():
    ring = sample_stroke(_circle(jitter=0.004), spacing=0.05)
    steps = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    assert stroke_is_closed(ring)
    assert np.linalg.norm(ring[-1] - ring[0]) == pytest.approx(steps.mean(), rel=0.05)  # no repeated start
    assert steps.mean() == pytest.approx(0.05, rel=0.05) and steps.std() < 0.05 * steps.mean()
    assert np.abs(np.hypot(ring[:, 0], ring[:, 1]) - 1.0).max() < 0.01


def test_a_small_loop_stays_closed_after_sampling():
    ring = sample_stroke(_circle(count=60, radius=0.05), spacing=0.05)
    assert stroke_is_closed(ring) and len(ring) == MIN_RING_POINTS


def test_sampling_damps_hand_jitter():
    raw = _circle(count=600, jitter=0.003, seed=3)  # a hand at 90 Hz: samples ~1 cm apart, jitter of millimetres
    smooth = sample_stroke(raw, spacing=0.05)
    raw_error = np.abs(np.hypot(raw[:, 0], raw[:, 1]) - 1.0).std() + np.abs(raw[:, 2] - 1.5).std()
    smooth_error = np.abs(np.hypot(smooth[:, 0], smooth[:, 1]) - 1.0).std() + np.abs(smooth[:, 2] - 1.5).std()
    assert smooth_error < 0.6 * raw_error


def test_an_open_stroke_keeps_its_ends_and_its_length():
    raw = np.stack([np.linspace(0, 1, 50), np.zeros(50), np.linspace(0, 2, 50)], axis=1)
    stroke = sample_stroke(raw, spacing=0.1)
    assert not stroke_is_closed(stroke)
    assert np.allclose(stroke[[0, -1]], raw[[0, -1]])
    assert arc_lengths(stroke)[-1] == pytest.approx(np.sqrt(5), rel=1e-3)


def test_closed_means_an_end_gap_under_a_tenth_of_the_arc():
    t = np.linspace(0, 1, 400)
    for share, closed in ((0.85, False), (0.95, True)):  # a circle's gap is ~2 pi (1 - share) / (2 pi share)
        arc = 2 * np.pi * share * t
        assert stroke_is_closed(np.stack([np.cos(arc), np.sin(arc), 0 * arc], axis=1)) is closed


def test_resampling_spaces_points_evenly_round_a_closed_polyline():
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    points = resample_polyline(square, 8, closed=True)
    assert np.allclose(np.linalg.norm(np.diff(np.concatenate([points, points[:1]]), axis=0), axis=1), 0.5)


@pytest.mark.parametrize("points, spacing, message", [
    (np.zeros((1, 3)), 0.05, "at least 2"),
    (np.array([[0, 0, 0], [np.nan, 0, 0], [1, 0, 0]]), 0.05, "finite"),
    (np.zeros((5, 3)), 0.05, "at least two spacings"),
    (np.zeros((5, 2)), 0.05, "shape"),
    (np.array([[0, 0, 0], [1, 0, 0.0]]), 0.0, "spacing"),
])
def test_unusable_strokes_are_refused_with_what_is_allowed(points, spacing, message):
    with pytest.raises(StrokeError, match=message):
        sample_stroke(points, spacing)
    assert issubclass(StrokeError, ValueError)
