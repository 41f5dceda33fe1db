"""From two 2D skeletons to a 3D main skeleton.

Two lifts of the front skeleton, each giving every front point its side column (its depth):
- `lift_on_side_strokes` (the default): branch by branch, parents first, the depths that keep the branch on the
  side drawing's strokes, smooth along it and starting where its parent is (a dynamic programme over the side
  columns), strokes a lifted branch has already explained costing more, so every drawn side branch is used.
- seed 001's: the skeleton point cloud by equal-height same-rank matching (digest 2.3) and the lift of the front
  skeleton through that cloud, consecutive points closer than L (digest 2.4). Matching by rank within a row
  ignores which branch a centre belongs to, so its branches leave the side drawing's strokes.

In: a front and a side `Skeleton2D` in one pixel frame (same rows for the same height). Out: (N, 3) lifted front
points (x, y, z) = (front column, row, side column), pixels (and seed 001's (M, 3) cloud).
"""
from __future__ import annotations

import cv2
import numpy as np

from ._two_view_lines import Skeleton2D, TwoViewError

__all__ = ["skeleton_pixels", "match_equal_height", "lift_main_skeleton", "lift_on_side_strokes", "LIFT_DISTANCE_PX",
           "DEPTH_STEP_COST", "REUSE_COST_PX"]

LIFT_DISTANCE_PX = 5.0  # L of digest 2.4: consecutive lifted points must be closer than this
# `lift_on_side_strokes`: the cost of a pixel of depth change between consecutive front points (a pixel apart),
# against a pixel of distance from the side strokes; and the extra cost, in pixels of distance, of lying on a side
# stroke an earlier branch already lies on (a branch starts on its parent's stroke, so this stays small).
DEPTH_STEP_COST = 0.25
REUSE_COST_PX = 3.0
REUSED_WITHIN_PX = 2  # side stroke pixels this close to a lifted point count as explained
DISTANCE_CAP_PX = 16  # a point farther than this from every side stroke costs no more for being farther
SIDE_MARGIN_PX = 8    # depths this far past the side drawing's strokes stay possible
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


def lift_on_side_strokes(front: Skeleton2D, side: Skeleton2D, step_cost: float = DEPTH_STEP_COST,
                         reuse_px: float = REUSE_COST_PX) -> np.ndarray:
    """The front skeleton lifted to 3D on the side drawing's strokes (module docstring).

    front : the front Skeleton2D, consecutive points about a pixel apart (`Skeleton2D.densified`); its branches
            are numbered after the branch they grow from.
    side  : the side Skeleton2D in the front's pixel frame (a row is the same height in both).
    A branch's depths z_0..z_k minimise sum_i cost_i(z_i) + step_cost * sum_i |z_i - z_(i-1)|, z_(-1) being its
    parent point's depth (the trunk's root: the side skeleton's root). cost_i(z) is the distance from (z, row_i)
    to the nearest side stroke pixel no earlier branch explained, or to any side stroke pixel plus `reuse_px`,
    whichever is less (distances capped at DISTANCE_CAP_PX); rows the side drawing does not reach cost nothing. A
    branch's tip adds its distance to the nearest side branch tip (unexplained, or any plus `reuse_px`).
    Returns (N, 3) float64 (x, y, z) pixels, z along the side view's columns.
    """
    side_px = skeleton_pixels(side)
    rows = np.floor(front.points[:, 1] + 0.5).astype(np.int64)
    low = int(min(rows.min(), side_px[:, 1].min()))
    high = int(max(rows.max(), side_px[:, 1].max()))
    left = int(side_px[:, 0].min()) - SIDE_MARGIN_PX
    width = int(side_px[:, 0].max()) - left + 1 + SIDE_MARGIN_PX
    strokes = np.zeros((high - low + 1, width), np.uint8)
    strokes[side_px[:, 1] - low, side_px[:, 0] - left] = 1
    drawn_rows = strokes.any(axis=1)
    unexplained = strokes.copy()
    to_any = _distance_to(strokes) + reuse_px
    tips = np.zeros_like(strokes)
    side_tips = np.floor(side.points[side.n_children == 0] + 0.5).astype(np.int64)
    tips[side_tips[:, 1] - low, side_tips[:, 0] - left] = 1
    to_any_tip = _distance_to(tips) + reuse_px
    columns = np.arange(width, dtype=np.float64)
    near = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * REUSED_WITHIN_PX + 1,) * 2)
    z = np.zeros(len(front))
    root_z = float(side.points[0, 0]) - left
    for b in range(front.n_branches):  # numbered after the branch they grow from: parents first
        members = np.flatnonzero(front.branch == b)  # in order along the branch (parent[i] < i)
        if members.size == 0:
            continue
        before = root_z if members[0] == 0 else z[front.parent[members[0]]]
        before_row = rows[members[0] if members[0] == 0 else front.parent[members[0]]]
        # Distances to what is still unexplained, in the branch's rows and a band around them (farther strokes
        # cost the cap either way).
        top = max(int(rows[members].min()) - low - DISTANCE_CAP_PX, 0)
        band = slice(top, int(rows[members].max()) - low + DISTANCE_CAP_PX + 1)
        at = rows[members] - low - top
        cost = np.minimum(to_any[band], _distance_to(unexplained[band]))
        unary = cost[at]
        unary[~drawn_rows[band][at]] = 0.0
        if front.n_children[members[-1]] == 0:  # a drawn tip ends where a side branch ends
            unary[-1] += np.minimum(to_any_tip[band], _distance_to(tips[band] & unexplained[band]))[at[-1]]
        z[members] = _smooth_path(unary, columns, before, step_cost)
        lifted = np.zeros_like(unexplained)
        path = np.column_stack([np.r_[before, z[members]], np.r_[before_row, rows[members]] - low])
        cv2.polylines(lifted, [np.round(path).astype(np.int32)], False, 1)  # jumps along a row explain the row
        unexplained &= cv2.dilate(lifted, near) == 0
    return np.column_stack([front.points, z + left])


def _distance_to(pixels: np.ndarray) -> np.ndarray:
    """(H, W) float64 Euclidean distance of every cell to the nearest set cell of a mask, at most DISTANCE_CAP_PX
    (also where the mask is empty)."""
    if not pixels.any():
        return np.full(pixels.shape, float(DISTANCE_CAP_PX))
    distance = cv2.distanceTransform((pixels == 0).astype(np.uint8), cv2.DIST_L2, 5)
    return np.minimum(distance, DISTANCE_CAP_PX).astype(np.float64)


def _smooth_path(unary: np.ndarray, columns: np.ndarray, before: float, step_cost: float) -> np.ndarray:
    """(K,) columns minimising sum_i unary[i, z_i] + step_cost * sum_i |z_i - z_(i-1)| with z_(-1) = before:
    a Viterbi pass whose L1 transitions are two running minima per step (no W x W table)."""
    k, width = unary.shape
    slope = step_cost * columns
    total = unary[0] + step_cost * np.abs(columns - before)
    back = np.empty((k, width), np.int64)
    for i in range(1, k):
        rising = total - slope  # from a column to the left: total[z'] + c (z - z')
        falling = (total + slope)[::-1]  # from the right: total[z'] + c (z' - z)
        low_left = np.minimum.accumulate(rising)
        low_right = np.minimum.accumulate(falling)[::-1]
        arg_left = np.maximum.accumulate(np.where(rising <= low_left, np.arange(width), 0))
        arg_right = (width - 1 - np.maximum.accumulate(np.where(falling <= np.minimum.accumulate(falling),
                                                                 np.arange(width), 0)))[::-1]
        from_left, from_right = low_left + slope, low_right - slope
        back[i] = np.where(from_left <= from_right, arg_left, arg_right)
        total = np.minimum(from_left, from_right) + unary[i]
    path = np.empty(k, np.int64)
    path[-1] = int(np.argmin(total))
    for i in range(k - 1, 0, -1):
        path[i - 1] = back[i, path[i]]
    return columns[path]
