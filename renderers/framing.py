"""The points a camera is framed by: the few vertices of a tree mesh that decide every fitted camera.

In: a TreeMesh; out: (K, 3) float32 metres, Z up, for `camera.perspective_camera`,
`silhouette_metric.switch_camera`, ...
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

__all__ = ["framing_points"]


def framing_points(tree) -> np.ndarray:
    """(K, 3) float32 metres: the vertices of the convex hull of a TreeMesh's vertices, or all of them when they
    span no volume. Cameras fitted to points (box centre, the distance at which all fit, near/far) depend only
    on extremes of linear or linear-fractional functions of the points, which convex hull vertices attain, so
    they come out bit-identical from a few hundred points instead of every vertex (and an asset fits dozens)."""
    points = np.concatenate([tree.bark.vertices, tree.leaves.vertices])
    try:
        return points[np.sort(ConvexHull(points.astype(np.float64)).vertices)]
    except QhullError:  # flat or too few points: no hull, and no cheaper set of extremes to take
        return points
