"""Twigs, radii and leaves of the two-view method (seed 001, digest 2.5-2.6): self-similar copies of parent
branches clipped by both crown outlines, pipe-model radii, one leaf card per last-level twig point.

In: the main skeleton (metres, Z up, base at the origin) and the two views' crown outlines. Out: a `Skeleton`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from species import Skeleton
from species.geometry import pipe_model_radii, rot_axis, unit_vectors
from species.geometry.topology import depth_levels, node_depths
from species.geometry.vectors import cross_rows, row_norms
from species.lsystem.turtle import leaf_cards

from ._two_view_lines import TwoViewError

__all__ = ["CrownOutline", "resample_skeleton", "grow_twigs", "add_leaves", "TWIG_DEFAULTS", "LEAF_DEFAULTS"]

# Digest 2.5 "Default we choose", with the fractions of the tree's height that make them scale-free.
TWIG_DEFAULTS = {
    "levels": 3, "children": 4, "sigma": (0.3, 0.6), "theta_deg": (30.0, 60.0), "phi_deg": (60.0, 180.0),
    "phi_target_deg": 137.5, "phi_spread_deg": 15.0, "bud_span": 0.7, "density_radius": 0.03,
    "density_limit": 6, "pipe_exponent": 2.5, "tip_radius": 0.002,
}
# The pipe exponent is the farm's 2.5, not the patent's 2: with ~1,600 twig tips on a drawn 8 m maple, exponent 2
# gives a trunk of 0.64 m radius, 2.5 gives 0.31 m (pass twig_options={"pipe_exponent": 2.0} to reproduce it).
# Digest 2.6: leaf angle 45 +- 15 deg, jitter +-0.3 segment, random roll. Size: a fraction of the tree height.
LEAF_DEFAULTS = {"tilt_deg": (30.0, 60.0), "jitter": 0.3, "length": 0.015, "aspect": 0.6}
_UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, eq=False)
class CrownOutline:
    """A crown outline in one view, and where world points fall in that view's image.

    mask   : (H, W) bool, True inside the crown outline, image pixels (row, column).
    axis   : the world axis along the image columns: 0 (X, the front view) or 1 (Y, the side view); world Z is up
             the image rows (orthographic, as the views are drawn).
    base   : (column, row) float pixels of the world origin (the tree base) in the image.
    pixels_per_metre : float, the view's scale.
    """

    mask: np.ndarray
    axis: int
    base: tuple[float, float]
    pixels_per_metre: float

    def __post_init__(self) -> None:
        mask = np.ascontiguousarray(np.asarray(self.mask, bool))
        if mask.ndim != 2:
            raise TwoViewError(f"an outline mask has shape {mask.shape}: allowed a 2-D (H, W) array")
        if self.axis not in (0, 1):
            raise TwoViewError(f"outline axis {self.axis!r} is invalid: allowed 0 (front, X) or 1 (side, Y)")
        if not np.isfinite(self.pixels_per_metre) or self.pixels_per_metre <= 0:
            raise TwoViewError(f"outline scale {self.pixels_per_metre!r} px/m is invalid: allowed a number > 0")
        mask.setflags(write=False)
        object.__setattr__(self, "mask", mask)

    def project(self, points: np.ndarray) -> np.ndarray:
        """(N, 2) float64 (column, row) pixels of world points (N, 3) metres."""
        points = np.asarray(points, np.float64).reshape(-1, 3)
        col = self.base[0] + points[:, self.axis] * self.pixels_per_metre
        row = self.base[1] - points[:, 2] * self.pixels_per_metre
        return np.column_stack([col, row])

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: each world point (N, 3) metres projects onto a pixel inside the outline."""
        pixel = np.floor(self.project(points) + 0.5).astype(np.int64)
        h, w = self.mask.shape
        inside = (pixel[:, 0] >= 0) & (pixel[:, 0] < w) & (pixel[:, 1] >= 0) & (pixel[:, 1] < h)
        out = np.zeros(len(pixel), bool)
        out[inside] = self.mask[pixel[inside, 1], pixel[inside, 0]]
        return out


def resample_skeleton(positions: np.ndarray, parent: np.ndarray, order: np.ndarray, radius: np.ndarray,
                      spacing: float) -> Skeleton:
    """A dense skeleton thinned to about `spacing` metres between nodes along every branch.

    positions (N, 3) metres, parent (N,) with parent[i] < i, order (N,) branch order, radius (N,) metres.
    Keeps the root, tips, forks and the first node past every multiple of `spacing` of arc length from the
    root; every other node is dropped and its children hang from its nearest kept ancestor.
    """
    positions = np.asarray(positions, np.float64)
    parent = np.asarray(parent, np.int64)
    n = len(positions)
    arc = np.zeros(n)
    seg = np.zeros(n)
    seg[1:] = row_norms(positions[1:] - positions[parent[1:]])
    depth = node_depths(parent)
    for nodes in depth_levels(depth):
        arc[nodes] = arc[parent[nodes]] + seg[nodes]
    children = np.bincount(parent[1:], minlength=n)
    keep = children != 1
    keep[0] = True
    keep[1:] |= np.floor(arc[1:] / spacing) > np.floor(arc[parent[1:]] / spacing)
    # A node whose order differs from its parent's starts a branch: keep the branch's first node.
    keep[1:] |= np.asarray(order)[1:] != np.asarray(order)[parent[1:]]
    ancestor = parent.copy()
    while True:
        moving = (ancestor >= 0) & ~keep[np.maximum(ancestor, 0)]
        if not moving.any():
            break
        ancestor[moving] = parent[ancestor[moving]]
    index = np.cumsum(keep) - 1
    kept = np.flatnonzero(keep)
    new_parent = np.where(ancestor[kept] >= 0, index[np.maximum(ancestor[kept], 0)], -1)
    return Skeleton(positions[kept], new_parent, np.asarray(radius)[kept], np.asarray(order)[kept])


def _frame_normal(tangent: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors perpendicular to unit tangents (N, 3)."""
    reference = np.where(np.abs(tangent[:, 2:3]) < 0.9, _UP, np.array([1.0, 0.0, 0.0]))
    return unit_vectors(cross_rows(tangent, reference))


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 3, 3) smallest rotations taking unit vectors a (N, 3) to unit vectors b (N, 3)."""
    axis = cross_rows(a, b)
    sin = row_norms(axis)
    cos = np.einsum("ij,ij->i", a, b)
    fallback = _frame_normal(a)  # a reversal turns about any perpendicular axis
    axis = np.where(sin[:, None] > 1e-9, axis / np.maximum(sin, 1e-300)[:, None], fallback)
    return rot_axis(axis, np.arctan2(sin, cos))


@dataclass(frozen=True)
class _Paths:
    """Parent branches of one level, end to end: nodes (K,) int64, points (K, 3) metres, offsets (P + 1,) int64,
    order (P,) int64 (the branches' own order)."""

    nodes: np.ndarray
    points: np.ndarray
    offsets: np.ndarray
    order: np.ndarray


def _segment_index(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For segments of `counts` (S,) items laid end to end: the segment (T,) and the index within it (T,)."""
    owner = np.repeat(np.arange(len(counts)), counts)
    return owner, np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)


def _draw_buds(paths: _Paths, rng: np.random.Generator, o: dict):
    """Bud parents (B,) and indices on them (B,): up to `children` distinct points of each parent's outer
    bud_span, neither its first nor its last point; then per bud sigma, theta (radians) and azimuth (radians,
    successive siblings a clipped N(target, spread) step apart)."""
    m = np.diff(paths.offsets)
    first = np.maximum(1, np.ceil((1.0 - o["bud_span"]) * (m - 1)).astype(np.int64))
    eligible = np.maximum(m - 1 - first, 0)
    owner, within = _segment_index(eligible)
    keys = rng.random(len(owner))
    order = np.lexsort((keys, owner))
    rank = _segment_index(eligible)[1]  # owner is sorted, so ranks within a parent follow the sorted order
    chosen = order[rank < np.minimum(int(o["children"]), eligible)[owner[order]]]
    chosen = chosen[np.lexsort((within[chosen], owner[chosen]))]
    parent, index = owner[chosen], first[owner[chosen]] + within[chosen]
    count = len(parent)
    sigma = rng.uniform(*o["sigma"], count)
    theta = np.radians(rng.uniform(*o["theta_deg"], count))
    steps = np.clip(rng.normal(o["phi_target_deg"], o["phi_spread_deg"], count), *o["phi_deg"])
    start = rng.uniform(0.0, 2 * np.pi, len(m))
    total = np.cumsum(steps)
    run_first = np.searchsorted(parent, parent)
    azimuth = start[parent] + np.radians(total - total[run_first])
    return parent, index, sigma, theta, azimuth


def _grow_level(paths: _Paths, density: cKDTree, outlines, rng: np.random.Generator, o: dict, height: float):
    """One level of twigs on `paths`: (bud node (C,), points (C_k, 3) per kept twig end to end, counts (C,),
    order (C,)) of the twigs that survive density and clipping, with their points cut at the first outside."""
    parent, index, sigma, theta, azimuth = _draw_buds(paths, rng, o)
    m = np.diff(paths.offsets)
    base = paths.offsets[parent]
    bud = base + index
    bud_points = paths.points[bud]
    # Density: points of other branches within the radius (the parent's own points do not count).
    radius = o["density_radius"] * height
    near = density.query_ball_point(bud_points, radius, return_length=True) if len(bud) else np.zeros(0, int)
    owner, within = _segment_index(m[parent])
    own_distance = row_norms(paths.points[base[owner] + within] - bud_points[owner])
    own = np.bincount(owner[own_distance <= radius], minlength=len(bud))
    ok = near - own <= o["density_limit"]
    parent, base, bud, bud_points, sigma, theta, azimuth = (a[ok] for a in (parent, base, bud, bud_points, sigma,
                                                                            theta, azimuth))
    # Templates: the first round(sigma m) points of the parent, turned to leave it by theta toward the azimuth.
    length = np.maximum(np.rint(sigma * m[parent]).astype(np.int64), 2)
    tangent = unit_vectors(paths.points[bud + 1] - paths.points[bud - 1])
    normal = _frame_normal(tangent)
    radial = np.cos(azimuth)[:, None] * normal + np.sin(azimuth)[:, None] * cross_rows(tangent, normal)
    chord = unit_vectors(paths.points[base + length - 1] - paths.points[base])
    turn = rot_axis(unit_vectors(cross_rows(tangent, radial)), theta) @ _align(chord, tangent)
    child, step = _segment_index(length - 1)
    offset = paths.points[base[child] + step + 1] - paths.points[base[child]]
    points = bud_points[child] + np.einsum("cij,cj->ci", turn[child], offset)
    # Clipping: each twig is cut at its first point outside either outline.
    inside = outlines[0].contains(points) & outlines[1].contains(points)
    firsts = np.cumsum(length - 1) - (length - 1)
    outside_at = np.where(inside, np.iinfo(np.int64).max, step)
    keep = np.minimum(np.minimum.reduceat(outside_at, firsts), length - 1) if len(points) else np.zeros(0, int)
    kept_points = points[step < keep[child]]
    alive = keep > 0
    return paths.nodes[bud][alive], kept_points, keep[alive], paths.order[parent][alive] + 1


def grow_twigs(main: Skeleton, front_outline: CrownOutline, side_outline: CrownOutline, rng: np.random.Generator,
               **options) -> tuple[Skeleton, np.ndarray]:
    """The full branch skeleton: twigs grown level by level as self-similar copies of their parent branches
    (digest 2.5), kept only where they project inside both crown outlines, with pipe-model radii (digest 2.6).

    main    : the main skeleton, metres, Z up, base at the origin; its branches are the first level's parents.
    front_outline, side_outline : the two views' CrownOutline (axis 0 and 1).
    rng     : numpy Generator; every draw comes from it.
    options : any of TWIG_DEFAULTS: levels (twig levels), children (N per parent), sigma (template share of the
              parent's points, U(lo, hi)), theta_deg (angle to the parent, U(lo, hi)), phi_deg and
              phi_target_deg, phi_spread_deg (sibling azimuth steps ~ N(target, spread) clipped to phi_deg),
              bud_span (buds on this outer share of the parent), density_radius (fraction of the height) and
              density_limit (a bud with more points of other branches within that radius is dropped),
              pipe_exponent, tip_radius (fraction of the height).
    A twig is cut at its first point outside either outline; one with no point left is dropped. A parent branch
    needs 3 points to carry children. The density search tree is rebuilt once per level.
    Returns the Skeleton (main nodes first, as given; radii by the pipe model, tips tip_radius x height) and
    (N,) uint8 twig level of each node (0 on the main skeleton).
    """
    unknown = sorted(set(options) - set(TWIG_DEFAULTS))
    if unknown:
        raise TwoViewError(f"twig option {unknown[0]!r} is unknown: allowed {', '.join(TWIG_DEFAULTS)}")
    o = {**TWIG_DEFAULTS, **options}
    height = max(float(main.positions[:, 2].max()), 1e-6)
    positions = [main.positions.astype(np.float64)]
    parents = [main.parent.astype(np.int64)]
    orders = [main.order.astype(np.int64)]
    levels = [np.zeros(len(main), np.int64)]
    nodes, offsets = main.branch_path_nodes
    long_enough = np.diff(offsets) >= 3
    keep_nodes = np.repeat(long_enough, np.diff(offsets))
    paths = _Paths(nodes[keep_nodes].astype(np.int64), main.positions[nodes[keep_nodes]].astype(np.float64),
                   np.concatenate([[0], np.cumsum(np.diff(offsets)[long_enough])]),
                   main.order[nodes[offsets[1:] - 1]][long_enough].astype(np.int64))
    count = len(main)
    outlines = (front_outline, side_outline)
    for level in range(1, int(o["levels"]) + 1):
        if len(paths.order) == 0:
            break
        density = cKDTree(np.concatenate(positions))
        buds, points, counts, order = _grow_level(paths, density, outlines, rng, o, height)
        if not len(buds):
            break
        ids = np.arange(count, count + len(points))
        firsts = np.cumsum(counts) - counts
        parent = ids - 1
        parent[firsts] = buds
        positions.append(points)
        parents.append(parent)
        orders.append(np.repeat(order, counts))
        levels.append(np.full(len(points), level))
        count += len(points)
        bud_points = np.concatenate(positions)[buds]
        paths = _Paths(np.insert(ids, firsts, buds), np.insert(points, firsts, bud_points, axis=0),
                       np.concatenate([[0], np.cumsum(counts + 1)]), order)
    parent = np.concatenate(parents)
    radii = pipe_model_radii(parent, o["tip_radius"] * height, o["pipe_exponent"])
    order = np.minimum(np.concatenate(orders), 255)
    skeleton = Skeleton(np.concatenate(positions), parent, radii, order)
    return skeleton, np.minimum(np.concatenate(levels), 255).astype(np.uint8)


def add_leaves(skeleton: Skeleton, level: np.ndarray, rng: np.random.Generator, **options) -> Skeleton:
    """The skeleton with one leaf card per node of the last twig level (digest 2.6; the main skeleton's tips when
    no twig grew): leaning tilt_deg U(lo, hi) out of the twig, randomly rolled about it, moved along its segment
    by U(-jitter, jitter) of the segment, length `length` x tree height and width aspect x length.

    level : (N,) twig level per node, as `grow_twigs` returns. options : any of LEAF_DEFAULTS.
    """
    unknown = sorted(set(options) - set(LEAF_DEFAULTS))
    if unknown:
        raise TwoViewError(f"leaf option {unknown[0]!r} is unknown: allowed {', '.join(LEAF_DEFAULTS)}")
    o = {**LEAF_DEFAULTS, **options}
    level = np.asarray(level)
    nodes = np.flatnonzero((level == level.max()) & (level > 0)) if level.max() > 0 else skeleton.tips
    nodes = nodes[nodes > 0]
    if not len(nodes):
        return skeleton
    height = max(skeleton.height, 1e-6)
    segment = skeleton.positions[nodes].astype(np.float64) - skeleton.positions[skeleton.parent[nodes]]
    heading = unit_vectors(segment)
    heading = np.where(row_norms(heading)[:, None] > 0.5, heading, _UP)
    left = _frame_normal(heading)
    frames = np.stack([heading, left, cross_rows(heading, left)], axis=2)
    points = skeleton.positions[nodes] + rng.uniform(-o["jitter"], o["jitter"], len(nodes))[:, None] * segment
    tilt = rng.uniform(*o["tilt_deg"], len(nodes))
    roll = rng.uniform(0.0, 2 * np.pi, len(nodes))
    length = o["length"] * height
    cards = leaf_cards(points, frames, length, o["aspect"] * length, tilt, roll)
    return Skeleton(skeleton.positions, skeleton.parent, skeleton.radius, skeleton.order, cards,
                    nodes.astype(np.int32))
