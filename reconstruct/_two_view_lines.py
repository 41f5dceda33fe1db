"""2D skeletons of the two-view method (seed 001): the `Skeleton2D` type, its error, and the tracer of 1-pixel
strokes (digest 2.1: 8/16-neighbour analysis, smallest-angle continuation, LIFO branch starts).

In: a (H, W) bool mask of connected 1-pixel strokes. Out: a `Skeleton2D` in pixel coordinates (x = column, y = row).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import math

import cv2
import numpy as np

from species.errors import TreefarmError

__all__ = ["TwoViewError", "Skeleton2D", "skeleton_2d_from_lines", "check_mask", "LINE_RADIUS_PX"]

# Radius given to every point of a 1-pixel stroke, which carries no width.
LINE_RADIUS_PX = 0.5
# A branch tip with fewer own points than this is a spur of a stroke junction, not a branch: dropped.
_MIN_BRANCH_POINTS = 3
# Points back along the branch that give its tangent (digest 2.1 default).
_TANGENT_BACK = 3
# Pieces named in the disconnected-strokes error.
_PIECES_NAMED = 4

# The 8-ring (3x3) and the 16-ring (outer ring of 5x5) as (dy, dx) offsets, the 16-ring in order around it.
_RING8 = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]
_RING16 = ([(-2, dx) for dx in range(-2, 3)] + [(dy, 2) for dy in range(-1, 3)] + [(2, dx) for dx in range(1, -3, -1)]
           + [(dy, -2) for dy in range(1, -2, -1)])
# Flat indices of both rings in a 5x5 window.
_FLAT8 = np.array([(dy + 2) * 5 + dx + 2 for dy, dx in _RING8])
_FLAT16 = np.array([(dy + 2) * 5 + dx + 2 for dy, dx in _RING16])


class TwoViewError(TreefarmError):
    """Input the two-view method cannot use: an image that is blank or not an image, views of different sizes,
    1-pixel strokes in several pieces, a height out of range."""


@dataclass(frozen=True, eq=False)
class Skeleton2D:
    """A tree drawn in one view, as a structure of arrays in that image's pixels.

    points : (N, 2) float64, pixels, (x = column, y = row, down). Point 0 is the root (the trunk base).
    parent : (N,) int32, parent point index, -1 for the root only; parent[i] < i.
    radius : (N,) float64, pixels, half the stroke width at each point (LINE_RADIUS_PX for 1-pixel strokes).
    branch : (N,) int32, the branch each point belongs to, numbered in tracing order (0 = the trunk). A branch's
             first point hangs from a point of an earlier branch.
    Arrays are read-only; derived views are cached properties.
    """

    points: np.ndarray
    parent: np.ndarray
    radius: np.ndarray
    branch: np.ndarray

    def __post_init__(self) -> None:
        arrays = {"points": np.asarray(self.points, np.float64), "parent": np.asarray(self.parent, np.int32),
                  "radius": np.asarray(self.radius, np.float64), "branch": np.asarray(self.branch, np.int32)}
        n = len(arrays["points"])
        if arrays["points"].shape != (n, 2) or n == 0:
            raise TwoViewError(f"points must have shape (N, 2) with N >= 1; got {arrays['points'].shape}")
        for name in ("parent", "radius", "branch"):
            if arrays[name].shape != (n,):
                raise TwoViewError(f"{name} must have shape ({n},); got {arrays[name].shape}")
        parent = arrays["parent"]
        if parent[0] != -1 or np.any(parent[1:] < 0) or np.any(parent[1:] >= np.arange(1, n)):
            raise TwoViewError("parent must be -1 at point 0 and in [0, i) at every other point i")
        for name, array in arrays.items():
            array = np.ascontiguousarray(array)
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    def __len__(self) -> int:
        return len(self.points)

    @property
    def n_branches(self) -> int:
        return int(self.branch.max()) + 1

    @cached_property
    def n_children(self) -> np.ndarray:
        """(N,) int64, number of children of each point."""
        return np.bincount(self.parent[1:], minlength=len(self))

    @cached_property
    def next_in_branch(self) -> np.ndarray:
        """(N,) int64, the child of each point on its own branch, or -1 at a branch's last point."""
        nxt = np.full(len(self), -1, np.int64)
        child = np.arange(1, len(self))
        same = self.branch[child] == self.branch[self.parent[child]]
        nxt[self.parent[child[same]]] = child[same]
        return nxt

    @cached_property
    def branch_order(self) -> np.ndarray:
        """(B,) int64, order of each branch: 0 for branch 0, one more than the branch it grows from otherwise."""
        order = np.zeros(self.n_branches, np.int64)
        firsts = np.flatnonzero(np.r_[True, self.branch[1:] != self.branch[self.parent[1:]]])
        for first in firsts[1:]:  # branches are numbered after the branch they grow from
            order[self.branch[first]] = order[self.branch[self.parent[first]]] + 1
        return order

    def transformed(self, scale: float, source_origin, target_origin) -> "Skeleton2D":
        """The same skeleton with points mapped p -> target_origin + scale (p - source_origin), radii scaled."""
        points = np.asarray(target_origin, np.float64) + scale * (self.points - np.asarray(source_origin, np.float64))
        return Skeleton2D(points, self.parent, self.radius * scale, self.branch)

    def densified(self, spacing: float = 1.0) -> "Skeleton2D":
        """The same skeleton with points inserted on every edge longer than `spacing` pixels, so consecutive points
        are at most `spacing` apart; inserted points take their edge's branch and interpolated radius."""
        n = len(self)
        child = np.arange(1, n)
        par = self.parent[1:].astype(np.int64)
        length = np.hypot(*(self.points[child] - self.points[par]).T)
        inserted = np.zeros(n, np.int64)
        inserted[1:] = np.maximum(np.ceil(length / spacing).astype(np.int64) - 1, 0)
        block = np.cumsum(inserted + 1) - (inserted + 1)  # first new index of each point's block
        new_index = block + inserted                       # each old point comes last in its block
        total = int(new_index[-1]) + 1
        owner = np.repeat(np.arange(n), inserted + 1)      # old point whose block each new index is in
        step = np.arange(total) - block[owner]             # 0 .. inserted[owner]
        t = (step + 1) / (inserted[owner] + 1)             # 1 at the old point itself
        start = np.where(owner > 0, self.parent[owner], 0)
        points = self.points[start] + t[:, None] * (self.points[owner] - self.points[start])
        radius = self.radius[start] + t * (self.radius[owner] - self.radius[start])
        parent = np.where(step == 0, new_index[start], np.arange(total) - 1)
        parent[0] = -1
        return Skeleton2D(points, parent, radius, self.branch[owner])


def check_mask(mask, name: str) -> np.ndarray:
    """(H, W) bool copy of a stroke mask; raises TwoViewError unless it is 2-D and has a stroke pixel."""
    mask = np.asarray(mask)
    if mask.ndim != 2 or min(mask.shape) < 1:
        raise TwoViewError(f"{name} mask has shape {mask.shape}: allowed a 2-D (H, W) array")
    mask = mask.astype(bool)
    if not mask.any():
        raise TwoViewError(f"{name} has no stroke pixels: draw the tree's trunk and main branches")
    return mask


def _require_connected(mask: np.ndarray, name: str, origin: tuple[int, int]) -> None:
    count, labels, stats, centroids = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if count <= 2:
        return
    areas = stats[1:, cv2.CC_STAT_AREA]
    biggest = np.argsort(-areas, kind="stable")[:_PIECES_NAMED]
    pieces = ", ".join(f"{areas[i]} px near (x={centroids[i + 1][0] + origin[0]:.0f}, "
                       f"y={centroids[i + 1][1] + origin[1]:.0f})"
                       for i in biggest)
    more = f" and {count - 1 - len(biggest)} more" if count - 1 > len(biggest) else ""
    raise TwoViewError(f"{name}: the 1-pixel strokes are in {count - 1} separate pieces ({pieces}{more}); "
                       f"connect every stroke to the tree, or draw with a brush (brush=True) whose strokes "
                       f"may be apart")


def _ring_patterns(stroke: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) int64 bit patterns of each stroke pixel's 16-ring and 8-ring stroke pixels (bit k = ring position
    k; 0 off the strokes), for a stroke mask padded by 2."""
    ys, xs = np.nonzero(stroke)
    p16 = np.zeros(stroke.shape, np.int64)
    p8 = np.zeros(stroke.shape, np.int64)
    for patterns, ring in ((p16, _RING16), (p8, _RING8)):
        bits = np.zeros(len(ys), np.int64)
        for bit, (dy, dx) in enumerate(ring):
            bits |= stroke[ys + dy, xs + dx].astype(np.int64) << bit
        patterns[ys, xs] = bits
    return p16, p8


def _touching(a: tuple[int, int], b: tuple[int, int]) -> bool:
    return max(abs(a[0] - b[0]), abs(a[1] - b[1])) <= 1


# For each 16-ring position: the 16-ring positions and the 8-ring positions it touches.
_TOUCH16 = [[j for j in range(16) if j != k and _touching(_RING16[k], _RING16[j])] for k in range(16)]
_TOUCH8 = [[j for j in range(8) if _touching(_RING16[k], _RING8[j])] for k in range(16)]


@lru_cache(maxsize=None)
def _ring_groups(p16: int) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """The touching groups of a 16-ring pattern (digest 2.1 step 1), each with the 8-ring positions next to it,
    nearest the group's centre first: ((16-ring positions), (8-ring positions)) per group."""
    on = [k for k in range(16) if p16 >> k & 1]
    seen: set[int] = set()
    out = []
    for k in on:
        if k in seen:
            continue
        members, todo = [], [k]
        seen.add(k)
        while todo:
            m = todo.pop()
            members.append(m)
            for j in _TOUCH16[m]:
                if p16 >> j & 1 and j not in seen:
                    seen.add(j)
                    todo.append(j)
        members.sort()
        cy = sum(_RING16[m][0] for m in members) / len(members)
        cx = sum(_RING16[m][1] for m in members) / len(members)
        near = sorted({j for m in members for j in _TOUCH8[m]},
                      key=lambda j: ((_RING8[j][0] - cy) ** 2 + (_RING8[j][1] - cx) ** 2, j))
        out.append((tuple(members), tuple(near)))
    return tuple(out)


def _candidates(p16: np.ndarray, p8: np.ndarray, fixed: np.ndarray, y: int, x: int) -> list[tuple[int, int]]:
    """The new points around O = (y, x) (padded coordinates): one unfixed 8-neighbour next to each 16-ring
    group of stroke pixels without a fixed point (digest 2.1, steps 1-3)."""
    groups = _ring_groups(int(p16[y, x]))
    if not groups:
        return []
    inner = int(p8[y, x])
    window = fixed[y - 2:y + 3, x - 2:x + 3].ravel()
    fixed16, fixed8 = window[_FLAT16].tolist(), window[_FLAT8].tolist()
    found: list[tuple[int, int]] = []
    for members, near in groups:
        if any(fixed16[k] for k in members):
            continue
        for j in near:
            if inner >> j & 1 and not fixed8[j]:
                point = (y + _RING8[j][0], x + _RING8[j][1])
                if point not in found:
                    found.append(point)
                break
    return found


def _tangent(coords: list[tuple[int, int]], parent: list[int], node: int) -> tuple[float, float]:
    """(dy, dx) unit direction into `node` from the point _TANGENT_BACK steps back (straight up at the root)."""
    back = node
    for _ in range(_TANGENT_BACK):
        if parent[back] < 0:
            break
        back = parent[back]
    if back == node:
        return -1.0, 0.0
    dy, dx = coords[node][0] - coords[back][0], coords[node][1] - coords[back][1]
    norm = math.hypot(dy, dx)
    return dy / norm, dx / norm


def _straightest(found: list[tuple[int, int]], coords, parent, current: int, starts: list | None,
                 fixed: np.ndarray) -> tuple[int, int]:
    """The candidate whose step from `current` deviates least from the branch tangent; with `starts`, the others
    are stored there as new branches at `current`, reserved in `fixed` so the continuing branch cannot take them."""
    ty, tx = _tangent(coords, parent, current)
    oy, ox = coords[current]
    cosine = [((py - oy) * ty + (px - ox) * tx) / math.hypot(py - oy, px - ox) for py, px in found]
    best = cosine.index(max(cosine))
    if starts is not None:
        for k, point in enumerate(found):
            if k != best:
                fixed[point] = True
                starts.append((current, point))
    return found[best]


def _tip_pixel(p8: np.ndarray, fixed: np.ndarray, y: int, x: int) -> list[tuple[int, int]]:
    """The unfixed stroke 8-neighbours of (y, x): at a branch end, its last pixel."""
    bits = int(p8[y, x])
    return [(y + dy, x + dx) for j, (dy, dx) in enumerate(_RING8) if bits >> j & 1 and not fixed[y + dy, x + dx]]


def skeleton_2d_from_lines(mask, name: str = "sketch") -> Skeleton2D:
    """The 2D skeleton of a drawing in connected 1-pixel strokes (digest 2.1).

    mask : (H, W) bool (or 0/1), True on stroke pixels. Strokes a few pixels wide are first thinned to 1 pixel
           (`cv2.ximgproc.thinning`, Zhang-Suen), which leaves clean 1-pixel strokes as they are.
    name : the view's name in error messages.
    Tracing starts at the lowest stroke pixel (the middle one if several share the lowest row). At each point
    the unfixed 16-ring groups give candidate points; the one whose direction deviates least from the branch
    tangent (from 3 points back) continues the branch, the others are stored as starts of new branches at that
    point and resumed last-in first-out. Where no group is left the branch takes its end pixel (an unfixed
    8-neighbour, which has no 16-ring group beyond it) and ends. Stroke pieces the local rule cannot reach (arms
    of a fork too narrow to separate in the 16-ring) are resumed from the skeleton point they touch, largest
    first. Tip branches with fewer than 3 points (spurs of a junction) are dropped.
    Returns a Skeleton2D with integer pixel points and radius LINE_RADIUS_PX.
    Raises TwoViewError when the mask is empty or its strokes are in more than one 8-connected piece.
    """
    mask = check_mask(mask, name)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    # Work in the strokes' bounding box, with a 3 px border (2 for the 16-ring, 1 for thinning).
    y0, x0 = rows[0] - 3, cols[0] - 3
    box = np.zeros((rows[-1] - rows[0] + 7, cols[-1] - cols[0] + 7), np.uint8)
    box[3:-3, 3:-3] = mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1]
    stroke = cv2.ximgproc.thinning(box * 255) > 0
    _require_connected(stroke, name, (x0, y0))
    p16, p8 = _ring_patterns(stroke)
    fixed = np.zeros_like(stroke)
    node_at = np.full(stroke.shape, -1, np.int64)
    coords: list[tuple[int, int]] = []
    parent: list[int] = []
    branch: list[int] = []

    def add(point: tuple[int, int], par: int, b: int) -> int:
        fixed[point] = True
        node_at[point] = len(coords)
        coords.append(point)
        parent.append(par)
        branch.append(b)
        return len(coords) - 1

    ys, xs = np.nonzero(stroke)
    lowest = ys.max()
    row_cols = np.sort(xs[ys == lowest])
    current = add((int(lowest), int(row_cols[len(row_cols) // 2])), -1, 0)
    starts: list[tuple[int, tuple[int, int]]] = []
    n_branches = 1
    while True:
        found = _candidates(p16, p8, fixed, *coords[current])
        if found:
            current = add(_straightest(found, coords, parent, current, starts, fixed), current, branch[current])
            continue
        last = _tip_pixel(p8, fixed, *coords[current])
        if last:  # the stroke's end pixel has no 16-ring group beyond it: take it, then end the branch
            add(_straightest(last, coords, parent, current, None, fixed), current, branch[current])
        while starts and node_at[starts[-1][1]] >= 0:  # a start another branch has reached since
            starts.pop()
        if starts:
            origin, point = starts.pop()
            current = add(point, origin, n_branches)
            n_branches += 1
            continue
        starts = _unreached_starts(stroke, fixed, node_at)
        if not starts:
            break
    points = np.array(coords, np.float64)[:, ::-1] + (x0, y0)  # (y, x) in the box -> (x, y) in the image
    return _drop_spurs(points, np.array(parent), np.array(branch))


def _unreached_starts(stroke: np.ndarray, fixed: np.ndarray, node_at: np.ndarray) -> list:
    """(origin point index, first pixel) of every stroke piece of at least _MIN_BRANCH_POINTS pixels the tracer
    did not reach, at its lowest pixel touching a skeleton point (pieces hang below their branch's top), the
    largest piece last (resumed first)."""
    left = (stroke & ~fixed).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(left, connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= _MIN_BRANCH_POINTS
    big[0] = False
    touching = cv2.dilate(fixed.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    ys, xs = np.nonzero(touching & big[labels])
    if not len(ys):
        return []
    label = labels[ys, xs]
    pick = np.lexsort((-xs, -ys, label))  # per label: largest row first, then largest column
    first = np.r_[True, label[pick][1:] != label[pick][:-1]]
    chosen = pick[first]
    starts = []
    for y, x in zip(ys[chosen].tolist(), xs[chosen].tolist()):
        window = node_at[y - 1:y + 2, x - 1:x + 2]
        starts.append((int(stats[labels[y, x], cv2.CC_STAT_AREA]), int(window[window >= 0].min()), (y, x)))
    starts.sort(key=lambda s: s[0])
    return [(origin, point) for _, origin, point in starts]


def _drop_spurs(points: np.ndarray, parent: np.ndarray, branch: np.ndarray) -> Skeleton2D:
    """The skeleton without tip branches shorter than _MIN_BRANCH_POINTS (branch ids renumbered densely)."""
    n = len(points)
    size = np.bincount(branch)
    has_child_branch = np.zeros(len(size), bool)
    child = np.arange(1, n)
    crossing = branch[child] != branch[parent[child]]
    has_child_branch[branch[parent[child[crossing]]]] = True
    spur = (size < _MIN_BRANCH_POINTS) & ~has_child_branch
    spur[0] = False
    keep = ~spur[branch]
    if keep.all():
        return Skeleton2D(points, parent, np.full(n, LINE_RADIUS_PX), branch)
    new_index = np.cumsum(keep) - 1
    kept_parent = np.where(parent[keep] >= 0, new_index[np.maximum(parent[keep], 0)], -1)
    _, new_branch = np.unique(branch[keep], return_inverse=True)
    return Skeleton2D(points[keep], kept_parent, np.full(int(keep.sum()), LINE_RADIUS_PX), new_branch)
