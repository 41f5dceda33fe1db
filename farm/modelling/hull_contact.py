"""The guard for rigid subtree moves (seed 000 ch. 4): whether the convex hulls of two point sets touch.

In: two point sets (A, 3) and (B, 3) float metres, any shape (flat, collinear, a single point). Out: the distance
between their convex hulls, by GJK (Gilbert-Johnson-Keerthi) on the Minkowski difference A - B with each set's
support taken over its scipy ConvexHull vertices, and the contact test built on it: touching counts as contact.
Apart from the asset library's collision capsules, which approximate branches for game engines.
"""
from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from species.errors import TreefarmError

__all__ = ["HullError", "hull_distance", "hulls_overlap", "hull_vertices"]

_MAX_ITERATIONS = 200
_RELATIVE_GAP = 1e-12    # GJK stops when the distance bound closes to this share of the distance squared
_CONTACT_SCALE = 1e-12   # distances under this share of the sets' size are rounding, i.e. contact
_FLAT = 1e-10            # a simplex whose thinnest extent is under this share of its widest has lost a dimension


class HullError(TreefarmError):
    """A point set that has no hull: empty, the wrong shape, or not finite."""


def hull_vertices(points) -> np.ndarray:
    """(H, 3) float64: the points that span the convex hull of points (P, 3); all of them when the set is flat,
    collinear or too small for a 3D hull (the support function does not need the hull's faces)."""
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or not len(points):
        raise HullError(f"a point set for the hull guard must have shape (P >= 1, 3); got {points.shape}")
    if not np.all(np.isfinite(points)):
        raise HullError("a point set for the hull guard has non-finite coordinates; allowed: finite metres")
    if len(points) < 5:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:
        return points


def _closest_on_simplex(simplex: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The point of conv(simplex) (k <= 4 points) nearest the origin and the smallest subset whose hull holds it.

    Every face of the simplex is tried: the origin's projection on the face's affine span counts when its
    barycentric weights are all >= 0; the nearest of those is the answer.
    """
    best, best_subset = None, None
    for size in range(1, len(simplex) + 1):
        for subset in combinations(range(len(simplex)), size):
            pts = simplex[list(subset)]
            if size == 1:
                weights = np.ones(1)
            else:
                edges = pts[1:] - pts[0]
                spread = np.linalg.svd(edges, compute_uv=False)
                if spread[-1] <= _FLAT * spread[0]:
                    continue  # affinely dependent: its hull is covered by the smaller subsets
                solution = np.linalg.lstsq(edges @ edges.T, -edges @ pts[0], rcond=None)[0]
                weights = np.concatenate([[1.0 - solution.sum()], solution])
                if np.any(weights < -1e-12):
                    continue
            point = weights @ pts
            if best is None or point @ point < best @ best - 1e-30:
                best, best_subset = point, np.array(subset)[weights > 1e-12] if size > 1 else np.array(subset)
    return best, simplex[best_subset]


def hull_distance(points_a, points_b) -> float:
    """Metres between the convex hulls of points_a (A, 3) and points_b (B, 3); 0.0 when they touch or overlap."""
    a, b = hull_vertices(points_a), hull_vertices(points_b)
    scale = max(float(np.ptp(np.concatenate([a, b]), axis=0).max()), 1.0)
    contact = _CONTACT_SCALE * scale

    def support(direction: np.ndarray) -> np.ndarray:  # farthest point of A - B along direction
        return a[np.argmax(a @ direction)] - b[np.argmin(b @ direction)]

    v = a[0] - b[0]
    simplex = v[None, :]
    for _ in range(_MAX_ITERATIONS):
        distance = float(np.sqrt(v @ v))
        if distance <= contact:
            return 0.0
        w = support(-v)
        if v @ v - v @ w <= _RELATIVE_GAP * (v @ v) + contact * distance:
            return distance  # no point of A - B lies nearer the origin than v by more than rounding
        # A full tetrahedron is kept only when the origin lies in it: v is then 0 and the next pass says so.
        v, simplex = _closest_on_simplex(np.concatenate([simplex, w[None, :]]))
    return float(np.sqrt(v @ v))


def hulls_overlap(points_a, points_b, tolerance: float = 0.0) -> bool:
    """True when the convex hulls of the two point sets overlap or touch, or come within `tolerance` metres."""
    if not (np.isfinite(tolerance) and tolerance >= 0):
        raise HullError(f"hull contact tolerance is {tolerance!r}; allowed: a finite length >= 0 metres")
    return hull_distance(points_a, points_b) <= tolerance
