"""From two 2D skeletons to a 3D main skeleton (seed 001): the skeleton point cloud by equal-height same-rank
matching (digest 2.3) and the lift of the front skeleton through that cloud, consecutive points closer than L
(digest 2.4).

In: a front and a side `Skeleton2D` in one pixel frame (same rows for the same height). Out: (M, 3) cloud points
(x, y, z) = (front column, row, side column) and (N, 3) lifted front points, pixels.
"""
from __future__ import annotations

import numpy as np

from ._two_view_lines import Skeleton2D, TwoViewError

__all__ = ["skeleton_pixels", "match_equal_height", "lift_main_skeleton", "LIFT_DISTANCE_PX"]

LIFT_DISTANCE_PX = 5.0  # L of digest 2.4: consecutive lifted points must be closer than this
_NEIGHBOURS = [(dx, dy) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dx, dy) != (0, 0)]


def skeleton_pixels(skeleton: Skeleton2D) -> np.ndarray:
    """(K, 2) int64 (x, y) pixels covered by the skeleton's edges drawn 8-connected (each edge sampled at
    max(|dx|, |dy|) + 1 steps, rounded), unique, sorted by row then column: the skeleton's centres per row."""
    pts = skeleton.points
    child = np.arange(1, len(skeleton))
    a, b = pts[skeleton.parent[child]], pts[child]
    steps = np.maximum(np.ceil(np.abs(b - a).max(axis=1)).astype(np.int64), 1) if len(child) else np.zeros(0, int)
    edge = np.repeat(np.arange(len(child)), steps + 1)
    t = (np.arange(len(edge)) - np.repeat(np.cumsum(steps + 1) - (steps + 1), steps + 1)) / steps[edge]
    samples = a[edge] + t[:, None] * (b[edge] - a[edge])
    pixels = np.floor(np.concatenate([samples, pts]) + 0.5).astype(np.int64)
    pixels = np.unique(pixels[:, ::-1], axis=0)[:, ::-1]  # unique sorts by (y, x)
    return np.ascontiguousarray(pixels)


def match_equal_height(front: Skeleton2D, side: Skeleton2D) -> np.ndarray:
    """The 3D skeleton point cloud of two views by equal-height matching (digest 2.3).

    front, side : the two views' skeletons in one pixel frame: a row is the same height in both (normalise the
                  side view first when the drawings' scales differ, see `two_view`).
    In every row the front's centres (its skeleton pixels, see `skeleton_pixels`) are numbered left to right
    k = 0..m-1 and the side's 0..n-1; front centre k takes side centre k mod n (equal numbers when m <= n; the
    digest's ((x - 1) mod n) + 1 rule for the extra ones when m > n). Rows without side centres give no points.
    Returns (M, 3) float64 points (x, y, z) = (front column, row, side column), pixels, sorted by row and x.
    """
    front_px, side_px = skeleton_pixels(front), skeleton_pixels(side)
    low = min(front_px[:, 1].min(), side_px[:, 1].min())
    rows = max(front_px[:, 1].max(), side_px[:, 1].max()) - low + 1
    side_count = np.bincount(side_px[:, 1] - low, minlength=rows)
    side_first = np.cumsum(side_count) - side_count
    front_count = np.bincount(front_px[:, 1] - low, minlength=rows)
    front_row = front_px[:, 1] - low
    rank = np.arange(len(front_px)) - (np.cumsum(front_count) - front_count)[front_row]
    n = side_count[front_row]
    has = n > 0
    match = side_first[front_row[has]] + rank[has] % n[has]
    return np.column_stack([front_px[has], side_px[match, 0]]).astype(np.float64)


def lift_main_skeleton(front: Skeleton2D, cloud: np.ndarray, distance: float = LIFT_DISTANCE_PX) -> np.ndarray:
    """The front skeleton lifted to 3D through the cloud (digest 2.4, our reading of the OCR).

    front    : the front Skeleton2D, its consecutive points about a pixel apart (see `Skeleton2D.densified`).
    cloud    : (M, 3) points (x, y, z) from `match_equal_height`, pixels.
    distance : L, pixels: a cloud point is used only if it lies closer than L to the previous lifted point.
    Each point looks up the cloud at its (x, y) rounded to a pixel (else at the 8 pixels around it), taking the
    candidate whose z is closest to its parent's (the previous point's). The root takes the candidate nearest the
    cloud's median z (the median itself if none). A point whose candidates are all L or farther from its parent
    steps one pixel toward the next point's candidate z (none when equal), or keeps the parent's z when there is
    no next point or it has no candidate. Every later branch starts from its parent point's z.
    Returns (N, 3) float64 (x, y, z) pixels, z along the side view's columns.
    """
    cloud = np.asarray(cloud, np.float64)
    if cloud.ndim != 2 or cloud.shape[1] != 3 or len(cloud) == 0:
        raise TwoViewError(f"the skeleton point cloud has shape {cloud.shape}: the two views share no row with "
                           f"strokes; draw both views of the same tree, base to top")
    lookup: dict[tuple[int, int], list[tuple[float, float, float]]] = {}
    keys = np.floor(cloud[:, :2] + 0.5).astype(np.int64)
    for (kx, ky), point in zip(keys.tolist(), cloud.tolist()):
        lookup.setdefault((kx, ky), []).append(point)

    def candidates(x: float, y: float) -> list[tuple[float, float, float]]:
        kx, ky = int(np.floor(x + 0.5)), int(np.floor(y + 0.5))
        found = lookup.get((kx, ky))
        if found:
            return found
        return [p for dx, dy in _NEIGHBOURS for p in lookup.get((kx + dx, ky + dy), ())]

    xy = front.points.tolist()
    parent = front.parent.tolist()
    nxt = front.next_in_branch.tolist()
    z = np.empty(len(xy))
    median = float(np.median(cloud[:, 2]))
    root = candidates(*xy[0])
    z[0] = min((p[2] for p in root), key=lambda v: abs(v - median)) if root else median
    limit = distance * distance
    for i in range(1, len(xy)):
        x, y = xy[i]
        px, py = xy[parent[i]]
        zp = z[parent[i]]
        close = [q[2] for q in candidates(x, y)
                 if (q[0] - px) ** 2 + (q[1] - py) ** 2 + (q[2] - zp) ** 2 < limit]
        if close:
            z[i] = min(close, key=lambda v: abs(v - zp))
            continue
        ahead = candidates(*xy[nxt[i]]) if nxt[i] >= 0 else []
        if ahead:
            target = min((q[2] for q in ahead), key=lambda v: abs(v - zp))
            z[i] = zp + float(np.clip(target - zp, -1.0, 1.0))
        else:
            z[i] = zp
    return np.column_stack([front.points, z])
