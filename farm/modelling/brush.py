"""The growth brush (seed 000 ch. 4, eq. 4.2-4.3): markers spawned round the controller while the trigger is held.

In: the controller's path (K, 3) float metres, Z up, the brush radius (metres) and density (markers per cubic
metre), a Generator. Out: markers (M, 3) float64 metres, uniform in balls of the brush radius centred uniformly
along the path. Growth later steers buds along the path (`grow.grow_model`'s brush_paths, eq. 4.2-4.3).
"""
from __future__ import annotations

import numpy as np

from species.errors import TreefarmError

from .strokes import arc_lengths

__all__ = ["BrushError", "brush_markers", "MAX_BRUSH_MARKERS"]

MAX_BRUSH_MARKERS = 50_000  # one stroke of the brush makes at most this many markers


class BrushError(TreefarmError):
    """A brush stroke that cannot paint: no path, a non-finite point, a radius or density out of range."""


def brush_markers(path, radius: float, density: float, rng: np.random.Generator) -> np.ndarray:
    """(M, 3) float64 metres: density * (swept volume) markers, each uniform in a ball of `radius` metres round a
    point drawn uniformly along `path` (K >= 1, 3). The swept volume is the tube plus its two end caps."""
    path = np.asarray(path, np.float64)
    if path.ndim != 2 or path.shape[1] != 3 or not len(path) or not np.all(np.isfinite(path)):
        raise BrushError(f"a brush path must be finite points of shape (K >= 1, 3); got shape {path.shape}")
    if not (np.isfinite(radius) and radius > 0):
        raise BrushError(f"brush radius is {radius!r}; allowed: a finite length > 0 metres")
    if not (np.isfinite(density) and density > 0):
        raise BrushError(f"brush density is {density!r}; allowed: a finite number > 0 markers per cubic metre")
    arc = arc_lengths(path)
    volume = np.pi * radius ** 2 * arc[-1] + 4.0 / 3.0 * np.pi * radius ** 3
    count = max(1, int(round(density * volume)))
    if count > MAX_BRUSH_MARKERS:
        raise BrushError(f"the brush stroke would spawn {count} markers; allowed: at most {MAX_BRUSH_MARKERS} "
                         "(a smaller radius, a lower density or a shorter stroke)")
    along = rng.random(count) * arc[-1]
    centres = np.stack([np.interp(along, arc, path[:, d]) for d in range(3)], axis=1)
    direction = rng.normal(size=(count, 3))
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    return centres + direction * (radius * np.cbrt(rng.random(count)))[:, None]
