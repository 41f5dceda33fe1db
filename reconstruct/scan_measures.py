"""Measures taken on a scan's own points beside its skeleton: the stem's diameter at breast height by a circle fit
to the stem points of a thin slice, and the crown's projection on the ground (convex hull area and the diameter
of its smallest enclosing circle).

In: (N, 3) float64 points in the skeleton's frame (Z up, metres, the tree's base at Z = 0) and the `Skeleton`
(where its trunk is). Out: a `StemCircle` or None, a `CrownProjection`. A circle fit that the points cannot
support (too few, too short an arc, a circle no stem could be) gives None, and the caller falls back to the
skeleton's radius.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from itertools import combinations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from species.skeleton import Skeleton

__all__ = ["StemCircle", "CrownProjection", "trunk_at_height", "stem_circle", "robust_circle", "covered_arc_deg",
           "crown_projection", "enclosing_circle", "SLICE_HALF_M", "WIDE_SLICE_HALF_M", "MIN_STEM_POINTS",
           "MIN_ARC_DEG", "CROWN_CELL_M"]

SLICE_HALF_M = 0.05        # the slice at breast height: 10 cm thick, thin enough that a lean or a taper barely shows
WIDE_SLICE_HALF_M = 0.15   # taken instead when the thin slice holds fewer than MIN_STEM_POINTS stem points
MIN_STEM_POINTS = 10       # fewer cannot pin a circle down against scanner noise
MIN_ARC_DEG = 90.0         # a shorter arc leaves the radius free (a flat arc fits any large circle)
SEARCH_RADII = 3.0         # stem points lie within this many skeleton radii of the trunk's axis ...
MIN_SEARCH_M = 0.3         # ... and never less than this (a skeleton radius can be far too thin), ...
LOST_TRUNK_SEARCH_M = 1.0  # ... or this where the skeleton's trunk stops below breast height (it may be off the stem)
CANDIDATE_POINTS = 24      # circles through every three of this many slice points are tried (2,024 of them)
MAX_SCORED_POINTS = 1500   # candidates are scored on at most about this many of the slice's points
INLIER_BAND_M = 0.02       # a point this near a candidate circle supports it: scanner noise and bark
OUTLIER_SIGMAS = 3.0       # residuals beyond this many robust deviations are not the stem (twigs, leaves, noise)
MIN_TOLERANCE_M = 0.005    # the smallest residual ever rejected: scanner noise on a clean stem
CROWN_CELL_M = 0.5         # grid cell for the crown's projection: a point alone in its cell and its 8 neighbours
                           # is a stray return, not crown


@dataclass(frozen=True)
class StemCircle:
    """A circle fitted to a stem slice. centre : (2,) float64 metres (x, y); radius : metres; n_points : the points
    kept; arc_deg : degrees of the circle they cover (360 less the widest gap between them); rms_m : their RMS
    distance from the circle; slice_half_m : the half-height of the slice they came from."""

    centre: np.ndarray
    radius: float
    n_points: int
    arc_deg: float
    rms_m: float
    slice_half_m: float


@dataclass(frozen=True)
class CrownProjection:
    """The tree's points projected on the ground plane. hull : (H, 2) float64 metres, the convex hull's corners
    counter-clockwise; area_m2 : its area; diameter_m : the diameter of the smallest circle enclosing it;
    n_points : the points projected (stray ones dropped)."""

    hull: np.ndarray
    area_m2: float
    diameter_m: float
    n_points: int


def trunk_at_height(skeleton: Skeleton, height: float) -> tuple[np.ndarray, float] | None:
    """((3,) float64 position, radius) of the trunk (branch 0) where its height above the base (z - z of node 0)
    first reaches `height`, interpolated between the two trunk nodes around it; None when the trunk is lower."""
    trunk = skeleton.branch_paths[0]
    positions = skeleton.positions[trunk].astype(np.float64)
    above = np.flatnonzero(positions[:, 2] - positions[0, 2] >= height)
    if len(above) == 0 or above[0] == 0:
        return None
    k = int(above[0])
    z0, z1 = positions[k - 1, 2] - positions[0, 2], positions[k, 2] - positions[0, 2]
    t = (height - z0) / (z1 - z0)
    r0, r1 = float(skeleton.radius[trunk[k - 1]]), float(skeleton.radius[trunk[k]])
    return positions[k - 1] + t * (positions[k] - positions[k - 1]), r0 + t * (r1 - r0)


def covered_arc_deg(offsets: np.ndarray) -> float:
    """Degrees of a circle covered by points at (M, 2) `offsets` from its centre: 360 less the widest angular gap."""
    if len(offsets) < 2:
        return 0.0
    angles = np.sort(np.arctan2(offsets[:, 1], offsets[:, 0]))
    gaps = np.diff(np.append(angles, angles[0] + 2 * math.pi))
    return float(360.0 - math.degrees(gaps.max()))


def _geometric_circle(xy: np.ndarray, centre: np.ndarray, radius: float,
                      iterations: int = 20) -> tuple[np.ndarray, float]:
    """Gauss-Newton on the points' distances to the circle (the geometric fit: unbiased on a short arc, where the
    algebraic fit that starts it shrinks the radius)."""
    params = np.array([centre[0], centre[1], radius], np.float64)
    for _ in range(iterations):
        offsets = xy - params[:2]
        distance = np.maximum(np.hypot(offsets[:, 0], offsets[:, 1]), 1e-12)
        residual = distance - params[2]
        jacobian = np.column_stack([-offsets / distance[:, None], -np.ones(len(xy))])
        step, *_ = np.linalg.lstsq(jacobian, -residual, rcond=None)
        params += step
        if np.abs(step).max() < 1e-7:
            break
    return params[:2].copy(), float(abs(params[2]))


def _circumcircles(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(K, 2) centres and (K,) radii of the circles through (K, 2) points a[i], b[i], c[i]; NaN where the three
    lie on a line."""
    d = 2.0 * (a[:, 0] * (b[:, 1] - c[:, 1]) + b[:, 0] * (c[:, 1] - a[:, 1]) + c[:, 0] * (a[:, 1] - b[:, 1]))
    d = np.where(np.abs(d) > 1e-12, d, np.nan)
    sa, sb, sc = (a * a).sum(1), (b * b).sum(1), (c * c).sum(1)
    centres = np.column_stack([sa * (b[:, 1] - c[:, 1]) + sb * (c[:, 1] - a[:, 1]) + sc * (a[:, 1] - b[:, 1]),
                               sa * (c[:, 0] - b[:, 0]) + sb * (a[:, 0] - c[:, 0]) + sc * (b[:, 0] - a[:, 0])]) / d[:, None]
    return centres, np.hypot(*(a - centres).T)


def _candidate_circles(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(C, 2) centres and (C,) radii of the circles through every three of up to CANDIDATE_POINTS of the points,
    taken evenly in angle about their mean (so a whole arc is sampled, not one dense patch); collinear triples left
    out."""
    angle = np.arctan2(*(xy - xy.mean(axis=0)).T[::-1])
    order = np.argsort(angle, kind="stable")
    picked = xy[order[np.unique(np.linspace(0, len(xy) - 1, min(CANDIDATE_POINTS, len(xy))).round().astype(int))]]
    i, j, k = np.array(list(combinations(range(len(picked)), 3))).T
    centres, radii = _circumcircles(picked[i], picked[j], picked[k])
    finite = np.isfinite(radii)
    return centres[finite], radii[finite]


def robust_circle(xy: np.ndarray, slice_half_m: float = SLICE_HALF_M, max_radius: float = math.inf,
                  around: np.ndarray | None = None) -> StemCircle | None:
    """The circle through (M, 2) float64 stem-slice points that most of them lie on, robust to twigs, leaves and a
    half-scanned stem: of the circles through three points (`_candidate_circles`, radius at most `max_radius`,
    centre within `max_radius` of `around` when given), the one with the most points within INLIER_BAND_M less the
    points inside it (a stem is solid: a circle through twigs around it holds the stem's own points); then
    refitted geometrically to the points near it, dropping those farther than OUTLIER_SIGMAS robust deviations
    (median absolute residual), until the kept set settles. None when fewer than MIN_STEM_POINTS stay."""
    if len(xy) < MIN_STEM_POINTS:
        return None
    centres, radii = _candidate_circles(xy)
    fits = radii <= max_radius
    if around is not None:
        fits &= np.hypot(*(centres - around).T) <= max_radius
    if not fits.any():
        return None
    centres, radii = centres[fits], radii[fits]
    scored = xy[::-(-len(xy) // MAX_SCORED_POINTS)]  # every k-th point: a dense slice scored at a bounded cost
    distance = np.hypot(scored[None, :, 0] - centres[:, None, 0], scored[None, :, 1] - centres[:, None, 1])
    offset = distance - radii[:, None]
    score = (np.abs(offset) <= INLIER_BAND_M).sum(axis=1) - (offset < -2 * INLIER_BAND_M).sum(axis=1)
    best = int(np.argmax(score))  # the first of equals: the same points give the same circle
    centre, radius = centres[best], float(radii[best])
    keep = np.abs(np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) - radius) <= INLIER_BAND_M
    for _ in range(10):
        if keep.sum() < MIN_STEM_POINTS:
            return None
        centre, radius = _geometric_circle(xy[keep], centre, radius)
        residual = np.hypot(xy[:, 0] - centre[0], xy[:, 1] - centre[1]) - radius
        spread = 1.4826 * float(np.median(np.abs(residual[keep] - np.median(residual[keep]))))
        settled = np.abs(residual) <= max(OUTLIER_SIGMAS * spread, MIN_TOLERANCE_M)
        if np.array_equal(settled, keep) or not np.isfinite(radius):
            break
        keep = settled
    if keep.sum() < MIN_STEM_POINTS or not np.isfinite(radius):
        return None
    return StemCircle(centre, radius, int(keep.sum()), covered_arc_deg(xy[keep] - centre),
                      float(np.sqrt(np.mean(residual[keep] ** 2))), slice_half_m)


def stem_circle(points: np.ndarray, skeleton: Skeleton, height: float) -> StemCircle | None:
    """The stem's circle at `height` above the base: the points of a SLICE_HALF_M slice there (WIDE_SLICE_HALF_M
    when too few) within SEARCH_RADII skeleton radii (at least MIN_SEARCH_M) of the trunk's axis (where the trunk
    is lower than `height`, of its node nearest that height, at least LOST_TRUNK_SEARCH_M), fitted by
    `robust_circle`. None when the points are
    too few, their arc under MIN_ARC_DEG, or the circle no stem there could be (centre or radius beyond the search
    disc)."""
    at = trunk_at_height(skeleton, height)
    least = MIN_SEARCH_M if at is not None else LOST_TRUNK_SEARCH_M
    if at is None:
        trunk = skeleton.branch_paths[0]
        nearest = trunk[np.argmin(np.abs(skeleton.positions[trunk, 2] - skeleton.positions[0, 2] - height))]
        at = (skeleton.positions[nearest].astype(np.float64), float(skeleton.radius[nearest]))
        at[0][2] = skeleton.positions[0, 2] + height
    axis, skeleton_radius = at
    search = max(SEARCH_RADII * skeleton_radius, least)
    horizontal = np.hypot(points[:, 0] - axis[0], points[:, 1] - axis[1])
    near = horizontal <= search
    circle = None
    for half in (SLICE_HALF_M, WIDE_SLICE_HALF_M):
        stem = near & (np.abs(points[:, 2] - axis[2]) <= half)
        if stem.sum() >= MIN_STEM_POINTS:
            circle = robust_circle(points[stem, :2], half, search, axis[:2])
            break
    if circle is None or circle.arc_deg < MIN_ARC_DEG or circle.radius > search \
            or np.hypot(*(circle.centre - axis[:2])) > search:
        return None
    return circle


def _kept_in_grid(xy: np.ndarray, cell: float) -> np.ndarray:
    """(M,) bool: points whose grid cell, or one of its 8 neighbours' cells, holds another point."""
    ij = np.floor((xy - xy.min(axis=0)) / cell).astype(np.int64) + 1
    width = int(ij[:, 0].max()) + 2
    key = ij[:, 0] + width * ij[:, 1]
    cells, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    neighbours = np.zeros(len(cells), np.int64)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                shifted = cells + di + width * dj
                where = np.clip(np.searchsorted(cells, shifted), 0, len(cells) - 1)
                neighbours += cells[where] == shifted
    return ((counts > 1) | (neighbours > 0))[inverse.ravel()]


def enclosing_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (2,) and radius of the smallest circle enclosing (M, 2) points (M small: a hull's corners), by the
    incremental construction (Welzl's, iterative) over the points taken farthest from their mean first, so a
    corner that moves the circle is met early."""
    order = np.argsort(-np.hypot(*(xy - xy.mean(axis=0)).T), kind="stable")
    points = xy[order]
    slack = 1e-9

    def outside(p, c, r):
        return math.hypot(p[0] - c[0], p[1] - c[1]) > r + slack

    centre, radius = points[0].copy(), 0.0
    for i in range(1, len(points)):
        if not outside(points[i], centre, radius):
            continue
        centre, radius = points[i].copy(), 0.0
        for j in range(i):
            if not outside(points[j], centre, radius):
                continue
            centre = 0.5 * (points[i] + points[j])
            radius = 0.5 * math.hypot(*(points[i] - points[j]))
            for k in range(j):
                if outside(points[k], centre, radius):
                    centre, radius = _circle_on(points[i], points[j], points[k])
    return centre, radius


def _circle_on(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float]:
    """The circle through three points; for three on a line, the one on their farthest pair."""
    centres, radii = _circumcircles(a[None], b[None], c[None])
    if np.isfinite(radii[0]):
        return centres[0], float(radii[0])
    p, q = max([(a, b), (a, c), (b, c)], key=lambda pair: math.hypot(*(pair[0] - pair[1])))
    return 0.5 * (p + q), 0.5 * math.hypot(*(p - q))


def crown_projection(points: np.ndarray, cell: float = CROWN_CELL_M) -> CrownProjection | None:
    """The ground projection of (N, 3) points: the convex hull of their (x, y), stray points (alone in a `cell` grid
    neighbourhood) left out; None when fewer than three points or all in a line."""
    xy = np.asarray(points, np.float64)[:, :2]
    if len(xy) >= 3:
        xy = xy[_kept_in_grid(xy, cell)]
    if len(xy) < 3:
        return None
    try:
        hull = ConvexHull(xy)
    except QhullError:  # every point on one line: no area
        return None
    corners = xy[hull.vertices]
    _, radius = enclosing_circle(corners)
    return CrownProjection(corners, float(hull.volume), 2.0 * radius, len(xy))
