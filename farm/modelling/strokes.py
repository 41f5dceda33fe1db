"""Hand-drawn strokes (seed 000 ch. 4): sparse sampling of raw controller or mouse samples, cubic Hermite joining,
and the closed/open test.

In: raw samples (K, 3) float metres, Z up, in drawing order. Out: smooth polylines (S, 3) float64 metres, evenly
spaced along their arc; a closed stroke comes back as a ring (its first point not repeated at the end).
"""
from __future__ import annotations

import numpy as np

from species.colonization import hermite_curve
from species.errors import TreefarmError
from species.geometry.vectors import row_norms

__all__ = ["StrokeError", "sample_stroke", "stroke_is_closed", "resample_polyline", "arc_lengths", "CLOSED_GAP",
           "MIN_RAW_POINTS", "MIN_RING_POINTS"]

CLOSED_GAP = 0.10          # a stroke is closed when its endpoint gap is under this share of its arc length
MIN_RAW_POINTS = 2         # raw samples a stroke needs at the least
_HERMITE_SAMPLES = 4       # curve samples per Hermite segment before the even resampling
# A ring of n even samples has an end gap of 1 / (n - 1) of its open arc: from 12 samples on it stays closed.
MIN_RING_POINTS = 12


class StrokeError(TreefarmError):
    """A stroke that cannot be used: too few points, not finite, or with no length."""


def _raw_points(points) -> np.ndarray:
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise StrokeError(f"a stroke must be points of shape (K, 3); got shape {points.shape}")
    if len(points) < MIN_RAW_POINTS:
        raise StrokeError(f"a stroke has {len(points)} point(s); allowed: at least {MIN_RAW_POINTS}")
    if not np.all(np.isfinite(points)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(points), axis=1))[0])
        raise StrokeError(f"stroke point {bad} is {points[bad].tolist()}; allowed: finite coordinates")
    return points


def arc_lengths(points: np.ndarray, closed: bool = False) -> np.ndarray:
    """(K,) or, closed, (K + 1,) float64 metres: the arc length at each point (the last entry of a closed one is
    the whole loop, back at the first point)."""
    path = np.concatenate([points, points[:1]]) if closed else points
    return np.concatenate([[0.0], np.cumsum(row_norms(np.diff(path, axis=0)))])


def resample_polyline(points: np.ndarray, count: int, closed: bool = False) -> np.ndarray:
    """(count, 3) float64: `count` points evenly spaced along a polyline (K, 3) metres, ends kept; a closed one is
    resampled round its loop, from its first point, without repeating it."""
    points = np.asarray(points, np.float64)
    arc = arc_lengths(points, closed)
    path = np.concatenate([points, points[:1]]) if closed else points
    at = np.linspace(0.0, arc[-1], count + 1 if closed else count)[: count]
    return np.stack([np.interp(at, arc, path[:, d]) for d in range(3)], axis=1)


def stroke_is_closed(points) -> bool:
    """True when the gap between a stroke's ends is under CLOSED_GAP of its arc length (open otherwise)."""
    points = _raw_points(points)
    length = arc_lengths(points)[-1]
    return bool(length > 0 and np.linalg.norm(points[-1] - points[0]) < CLOSED_GAP * length)


def _sparse_controls(points: np.ndarray, spacing: float) -> np.ndarray:
    """Control points: the raw samples cut into runs that each reach `spacing` metres from their first sample, and
    each run replaced by its mean (averaging damps hand jitter; cutting by distance, not by the jittery arc
    length, keeps many samples per run), with the stroke's first and last samples kept as its ends."""
    starts, start = [], 0
    while start < len(points):  # one pass per run, each a vectorized search over the samples left
        starts.append(start)
        far = np.flatnonzero(row_norms(points[start:] - points[start]) >= spacing)
        start = start + int(far[0]) if len(far) else len(points)
    runs = np.repeat(np.arange(len(starts)), np.diff(np.append(starts, len(points))))
    count = np.bincount(runs)
    means = np.stack([np.bincount(runs, points[:, d]) for d in range(3)], axis=1) / count[:, None]
    controls = np.concatenate([points[:1], means[1:-1], points[-1:]]) if len(means) > 2 else points[[0, -1]]
    keep = np.concatenate([[True], row_norms(np.diff(controls, axis=0)) > 1e-9 * spacing])
    return controls[keep]


def sample_stroke(points, spacing: float = 0.05) -> np.ndarray:
    """(S, 3) float64 metres: raw samples (K >= 2, 3) turned into a smooth stroke with points `spacing` apart.

    Raw samples are averaged per `spacing` of arc, the averages joined by a cubic Hermite (Catmull-Rom) curve and
    the curve resampled evenly. A closed stroke (`stroke_is_closed`) is joined round its loop and returned as a
    ring without its first point repeated. Raises StrokeError for fewer than 2 points, non-finite values, a
    non-positive spacing, or a stroke shorter than two spacings.
    """
    points = _raw_points(points)
    if not (np.isfinite(spacing) and spacing > 0):
        raise StrokeError(f"stroke spacing is {spacing!r}; allowed: a finite length > 0 metres")
    length = arc_lengths(points)[-1]
    if length < 2 * spacing:
        raise StrokeError(f"the stroke is {length:.4g} m long; allowed: at least two spacings "
                          f"({2 * spacing:.4g} m)")
    closed = stroke_is_closed(points)
    controls = _sparse_controls(points, spacing)
    if closed:
        if len(controls) > 3 and np.linalg.norm(controls[-1] - controls[0]) < spacing:
            controls = controls[:-1]  # the closing sample sits on the start: the loop joins there
        if len(controls) < 3:
            raise StrokeError(f"the closed stroke has {len(controls)} distinct control points after sampling; "
                              "allowed: at least 3 (draw a larger loop or a smaller spacing)")
        # Pad one point each side so the Hermite tangents at the join are the loop's own, then keep one turn.
        padded = np.concatenate([controls[-1:], controls, controls[:2]])
        curve = hermite_curve(padded, _HERMITE_SAMPLES)
        ring = curve[_HERMITE_SAMPLES: _HERMITE_SAMPLES * (len(controls) + 1)]
        perimeter = arc_lengths(ring, closed=True)[-1]
        return resample_polyline(ring, max(MIN_RING_POINTS, int(round(perimeter / spacing))), closed=True)
    curve = hermite_curve(controls, _HERMITE_SAMPLES)
    return resample_polyline(curve, max(2, int(round(arc_lengths(curve)[-1] / spacing)) + 1))
