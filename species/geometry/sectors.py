"""Faces split among planes crossed on one axis, each face to the plane it lies nearest (the impostor's vertical
planes, the crossed twig cards about a cluster's principal axis).

In: (F,) angles (degrees) of face centroids about the axis. Out: each face's sector, its neighbouring sector and
whether it lies close enough to that neighbour to be drawn on both planes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["plane_sectors"]


def plane_sectors(angle: np.ndarray, planes: int, overlap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For planes crossed at 180 / `planes` degrees, plane p's line at p * 180 / planes degrees from the angles'
    zero: (F,) int64 sector of each angle (degrees, any range; the plane whose line is within 90 / planes degrees
    of it, on either side of the axis), (F,) int64 the neighbouring sector on the angle's side, and (F,) bool,
    True where the angle lies in the outer `overlap` share of its sector next to that neighbour."""
    width = 180.0 / planes
    position = ((np.asarray(angle, np.float64) + 0.5 * width) % 180.0) / width
    sector = np.floor(position).astype(np.int64) % planes
    across = position - np.floor(position)  # 0..1 across the sector
    neighbour = np.where(across < 0.5, sector - 1, sector + 1) % planes
    return sector, neighbour, np.abs(across - 0.5) > 0.5 - overlap
