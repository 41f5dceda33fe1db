"""Per-marker steering of self-organizing growth: the attraction direction field (thesis eq. 3.6) and brush
strokes (eq. 4.2-4.3), plus Hermite guide curves and stroke tubes for using them in batch.

In: a field callable or array, or stroke polylines (metres). Out: a steering term per bud added to V_opt.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.interpolate import CubicHermiteSpline
from scipy.spatial import cKDTree

from ..geometry.vectors import unit_vectors
from .growth_space import GrowthSpaceError, PointSpace

__all__ = ["MarkerSteering", "revolved_field", "hermite_curve", "stroke_tube"]


def _resample(stroke: np.ndarray, spacing: float) -> np.ndarray:
    """A polyline (K, 3) resampled at about `spacing` metres along its arc length."""
    stroke = np.asarray(stroke, np.float64)
    if stroke.ndim != 2 or stroke.shape[1] != 3 or len(stroke) < 2:
        raise GrowthSpaceError(f"a stroke must be a polyline of shape (K >= 2, 3); got {stroke.shape}")
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(stroke, axis=0), axis=1))])
    samples = np.linspace(0.0, arc[-1], max(2, int(np.ceil(arc[-1] / spacing)) + 1))
    return np.stack([np.interp(samples, arc, stroke[:, d]) for d in range(3)], axis=1)


@dataclass(frozen=True)
class MarkerSteering:
    """Directions the markers carry, pulling the buds that perceive them.

    attraction : a field: callable mapping points (M, 3) metres to directions (M, 3), or an (M, 3) array
                 aligned with explicit markers. Adds attraction_weight * mean(v_trac) over a bud's markers
                 (eq. 3.6).
    strokes    : brush strokes, polylines (K, 3) metres. Each marker takes the tangent of the nearest stroke
                 point, weighted by a Gaussian of its distance d: exp(-d^2 / 2 sigma^2) (eq. 4.2); a bud adds
                 the weighted mean (eq. 4.3, normalized by the weights so sigma does not set the strength).
    sigma      : metres, the Gaussian width (digest: half the stroke tube radius).
    """

    attraction: Callable[[np.ndarray], np.ndarray] | np.ndarray | None = None
    strokes: Sequence[np.ndarray] = field(default_factory=tuple)
    sigma: float = 0.075

    def at(self, markers: np.ndarray) -> "_BoundSteering":
        """The per-marker fields for these markers (M, 3) metres."""
        attraction = None
        if self.attraction is not None:
            attraction = self.attraction(markers) if callable(self.attraction) else self.attraction
            attraction = unit_vectors(np.asarray(attraction, np.float64))
            if attraction.shape != markers.shape:
                raise GrowthSpaceError(f"attraction directions have shape {attraction.shape}; the markers "
                                       f"need {markers.shape}")
        stroke_dir = stroke_weight = None
        if len(self.strokes):
            if not self.sigma > 0:
                raise GrowthSpaceError(f"stroke sigma must be > 0 metres; got {self.sigma}")
            resampled = [_resample(s, self.sigma / 2) for s in self.strokes]  # few strokes, loop is fine
            points = np.concatenate(resampled)
            tangents = np.concatenate([unit_vectors(np.gradient(s, axis=0)) for s in resampled])
            distance, nearest = cKDTree(points).query(markers, k=1)
            stroke_dir = tangents[nearest]
            stroke_weight = np.exp(-0.5 * (distance / self.sigma) ** 2)
        return _BoundSteering(attraction, stroke_dir, stroke_weight)


@dataclass(frozen=True)
class _BoundSteering:
    attraction: np.ndarray | None
    stroke_dir: np.ndarray | None
    stroke_weight: np.ndarray | None

    def per_bud(self, marker: np.ndarray, owner: np.ndarray, buds: int, attraction_weight: float) -> np.ndarray:
        """(B, 3) steering added to each bud's V_opt from the markers (indices) it owns."""
        steer = np.zeros((buds, 3))
        if self.attraction is not None:
            count = np.maximum(np.bincount(owner, minlength=buds), 1)
            for d in range(3):
                steer[:, d] += attraction_weight * np.bincount(owner, self.attraction[marker, d], buds) / count
        if self.stroke_dir is not None:
            weight = self.stroke_weight[marker]
            total = np.bincount(owner, weight, buds)
            for d in range(3):
                pulled = np.bincount(owner, weight * self.stroke_dir[marker, d], buds)
                steer[:, d] += np.divide(pulled, total, out=np.zeros(buds), where=total > 1e-12)
        return steer


def revolved_field(directions: np.ndarray, extent: Sequence[float]) -> Callable[[np.ndarray], np.ndarray]:
    """A 3D field from a 2D image field revolved about the vertical axis through x = 0 (digest 1.12).

    directions : (H, W, 2) float, image-plane (x right, z up) directions per pixel; column 0 at x = extent[0],
                 row 0 at z = extent[3]. A point at horizontal radius rho and height h averages the field at
                 (+rho, h) and the mirror of (-rho, h), and turns the horizontal part to its own azimuth.
    """
    directions = np.asarray(directions, np.float64)
    x0, x1, z0, z1 = map(float, extent)
    height, width = directions.shape[:2]

    def field_at(points: np.ndarray) -> np.ndarray:
        rho = np.hypot(points[:, 0], points[:, 1])
        row = np.clip(((z1 - points[:, 2]) / (z1 - z0) * height).astype(int), 0, height - 1)

        def read(x):
            col = np.clip(((x - x0) / (x1 - x0) * width).astype(int), 0, width - 1)
            return directions[row, col]

        right, left = read(rho), read(-rho)
        outward = 0.5 * (right[:, 0] - left[:, 0])
        up = 0.5 * (right[:, 1] + left[:, 1])
        azimuth = np.arctan2(points[:, 1], points[:, 0])
        return np.stack([outward * np.cos(azimuth), outward * np.sin(azimuth), up], axis=1)

    return field_at


def hermite_curve(points: np.ndarray, samples_per_segment: int = 8) -> np.ndarray:
    """(S, 3) float64: a Catmull-Rom Hermite curve through control points (K >= 2, 3) metres."""
    points = np.asarray(points, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2:
        raise GrowthSpaceError(f"a guide curve needs control points (K >= 2, 3); got {points.shape}")
    tangents = np.gradient(points, axis=0)  # 0.5 * (P[i+1] - P[i-1]) inside, one-sided at the ends
    t = np.arange(len(points), dtype=np.float64)
    curve = CubicHermiteSpline(t, points, tangents, axis=0)
    return curve(np.linspace(0, t[-1], (len(points) - 1) * samples_per_segment + 1))


def stroke_tube(strokes: Sequence[np.ndarray], radius: float) -> PointSpace:
    """The growth space of brush strokes: everything within `radius` metres of any stroke."""
    points = np.concatenate([_resample(s, radius / 3) for s in strokes])
    return PointSpace(points, radius)
