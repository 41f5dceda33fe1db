"""Seed 003's editing of a skeleton measured from a point cloud: trunk identification (Algorithm 2), pruning of
over-long twigs (Algorithm 3), grafts of noisy copies of the tree's own branches into the crown's gaps
(Algorithms 4-8), and leafy phyllotaxis twigs at the tips; `complete` chains them.

In: a `Skeleton` (Z up, metres; the cloud-to-skeleton method's output), a numpy Generator, and optionally the
scan's `ScanReach` (its points' convex hull and ground plane). Out: a new Skeleton that `build_mesh` meshes. With a
reach, what completion adds stays inside it: a gap is grafted only where the scan's points are sparse too, and
added nodes and leaf cards below the ground or beyond the hull's margin are cut; measured nodes are never removed.
Randomness comes only from the Generator passed in: the same seed gives the same arrays.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from species.errors import ParameterError
from species.geometry.topology import depth_levels
from species.geometry.vectors import unit_vectors
from species.lsystem.graft import extract_subtree, graft, side_anchor
from species.lsystem.lstring_io import lstring_round_trip
from species.lsystem.phyllotaxis import PATTERNS, add_twigs
from species.skeleton import LEAF_CARD_CORNERS, Skeleton

__all__ = ["identify_trunk", "prune_long_twigs", "crown_sector_lengths", "fill_gaps", "complete", "ScanReach",
           "HULL_MARGIN_M",
           "RADIUS_THRESHOLD", "DEGREE_THRESHOLD", "GAP_SECTORS", "GAP_RATIO", "DEGREE_DIFF", "DIST_DIFF_PERCENT"]

# Digest 3.4 (Algorithm 2): a child continues the trunk when at least this share of the thickest child's radius
# and within this angle of its direction.
RADIUS_THRESHOLD, DEGREE_THRESHOLD = 0.7, 30.0
# Gap finding (ours): the crown is cut into this many azimuth sectors around the trunk, and a sector holding
# less than this share of the median sector's branch length is a gap.
GAP_SECTORS, GAP_RATIO = 12, 0.25
# Digest 3.7 (Algorithm 6): each grafted copy's angles get U(+-10) degrees, its lengths U(1 -+ 0.15).
DEGREE_DIFF, DIST_DIFF_PERCENT = 10.0, 0.15
# At most this many grafts fill one gap (a run of neighbouring gap sectors).
MAX_GRAFTS_PER_GAP = 3
# Issue 50: nothing added lies farther than this outside the scan's convex hull.
HULL_MARGIN_M = 1.0
_ROWS_AT_ONCE = 1024  # positions measured against the hull's planes at a time (`ScanReach.outside`)


@dataclass(frozen=True, eq=False)
class ScanReach:
    """Where completion may add wood and leaves: above `ground` (Z, metres), no higher than the highest point, and
    within `margin` metres of the convex hull of `points` ((N, 3), the skeleton's frame). Points too few or flat
    for a hull bound only by the ground and the top."""

    points: np.ndarray
    ground: float
    margin: float = HULL_MARGIN_M

    def __post_init__(self) -> None:
        points = np.asarray(self.points, np.float64)
        try:
            planes = ConvexHull(points).equations if len(points) >= 4 else np.zeros((0, 4))
        except QhullError:
            planes = np.zeros((0, 4))
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "_planes", planes)

    def outside(self, xyz: np.ndarray, radius: np.ndarray | float = 0.0) -> np.ndarray:
        """(M,) bool: balls of `radius` (a tube's; 0 for points) about the positions that reach below the ground,
        whose centres are above the highest point, or that reach beyond the margin (by their farthest hull plane,
        exact off a face)."""
        xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
        low = (xyz[:, 2] - radius < self.ground) | (xyz[:, 2] > self.points[:, 2].max(initial=-np.inf))
        if not len(self._planes):
            return low
        farthest = np.empty(len(xyz))
        normals, offsets = self._planes[:, :3].T, self._planes[:, 3]
        for start in range(0, len(xyz), _ROWS_AT_ONCE):  # rows by the block: a block's products stay in the cache
            block = xyz[start:start + _ROWS_AT_ONCE] @ normals
            block += offsets
            block.max(axis=1, initial=-np.inf, out=farthest[start:start + _ROWS_AT_ONCE])
        return low | (farthest + radius > self.margin)


def keep_within_reach(skeleton: Skeleton, reach: ScanReach, first_added: int) -> Skeleton:
    """The skeleton less the added nodes (index `first_added` on) outside `reach` (their tube's bottom below the
    ground, or beyond the hull's margin), each with everything under it, and less every leaf card with a corner
    outside. Nodes before `first_added` are never removed."""
    drop = np.zeros(len(skeleton), bool)
    added = slice(first_added, None)
    drop[added] = reach.outside(skeleton.positions[added], skeleton.radius[added].astype(np.float64))
    for level in depth_levels(skeleton.depth):
        drop[level] |= drop[skeleton.parent[level]]
    trimmed = skeleton.subset(~drop) if drop.any() else skeleton
    if not len(trimmed.leaves):
        return trimmed
    corners = np.einsum("mij,cj->mci", trimmed.leaves.astype(np.float64)[:, :3, :3], LEAF_CARD_CORNERS) \
        + trimmed.leaves.astype(np.float64)[:, None, :3, 3]
    inside = ~reach.outside(corners).reshape(len(trimmed.leaves), -1).any(axis=1)
    if inside.all():
        return trimmed
    return Skeleton(positions=trimmed.positions, parent=trimmed.parent, radius=trimmed.radius, order=trimmed.order,
                    leaves=trimmed.leaves[inside], leaf_node=trimmed.leaf_node[inside])


def _check_mask(skeleton: Skeleton, mask, key: str) -> np.ndarray:
    mask = np.asarray(mask)
    if mask.dtype != bool or mask.shape != (len(skeleton),):
        raise ParameterError(key, f"{mask.dtype} array of shape {mask.shape}", f"a ({len(skeleton)},) bool mask")
    return mask


# ---------------------------------------------------------------------------------------------- trunk
def identify_trunk(skeleton: Skeleton, radius_threshold: float = RADIUS_THRESHOLD,
                   degree_threshold: float = DEGREE_THRESHOLD) -> np.ndarray:
    """Algorithm 2: (N,) bool, the trunk nodes. The root is trunk; below a trunk node with one child the child is
    trunk; below one with several, every child whose radius is at least `radius_threshold` of the thickest
    child's and whose edge is within `degree_threshold` degrees of the thickest child's edge is trunk (>=, and
    the child, not the root, is added: the digest's fixes), so co-dominant leaders are all trunk; the thickest
    child (lowest index on ties) always qualifies. One vectorized step per depth level, no walk over nodes.
    """
    if not 0 < radius_threshold <= 1:
        raise ParameterError("radius_threshold", radius_threshold, "a share of the thickest child's radius in (0, 1]")
    if not 0 <= degree_threshold <= 180:
        raise ParameterError("degree_threshold", degree_threshold, "degrees in [0, 180]")
    n = len(skeleton)
    trunk = np.zeros(n, bool)
    trunk[0] = True
    if n == 1:
        return trunk
    child = np.arange(1, n)
    parent = skeleton.parent[1:].astype(np.int64)
    radius = skeleton.radius.astype(np.float64)
    keys = np.lexsort((child, -radius[child], parent))  # per parent: thickest child first, lowest index on ties
    first = np.ones(len(keys), bool)
    first[1:] = parent[keys][1:] != parent[keys][:-1]
    thickest = np.full(n, -1, np.int64)
    thickest[parent[keys][first]] = child[keys][first]
    base = thickest[parent]
    here = skeleton.positions[parent].astype(np.float64)
    base_direction = unit_vectors(skeleton.positions[base] - here)
    direction = unit_vectors(skeleton.positions[child] - here)
    aligned = np.einsum("ij,ij->i", direction, base_direction) >= np.cos(np.radians(degree_threshold))
    qualifies = np.zeros(n, bool)
    qualifies[child] = (skeleton.n_children[parent] == 1) | (child == base) | (
        (radius[child] >= radius_threshold * radius[base]) & aligned)
    for level in depth_levels(skeleton.depth):
        trunk[level] = trunk[skeleton.parent[level]] & qualifies[level]
    return trunk


def _with_trunk_orders(skeleton: Skeleton, trunk: np.ndarray) -> Skeleton:
    """Orders made to agree with the trunk mask: trunk nodes 0, every other node at least 1."""
    order = np.where(trunk, 0, np.maximum(skeleton.order, 1))
    return Skeleton(positions=skeleton.positions, parent=skeleton.parent, radius=skeleton.radius, order=order,
                    leaves=skeleton.leaves, leaf_node=skeleton.leaf_node)


# -------------------------------------------------------------------------------------------- pruning
def _twig_steps(skeleton: Skeleton) -> np.ndarray:
    """(N,) int64, edges from each node up to its first ancestor with two or more children; -1 where none."""
    branching = skeleton.n_children >= 2
    steps = np.full(len(skeleton), -1, np.int64)
    for level in depth_levels(skeleton.depth):
        above = skeleton.parent[level]
        steps[level] = np.where(branching[above], 1, np.where(steps[above] >= 1, steps[above] + 1, -1))
    return steps


def prune_long_twigs(skeleton: Skeleton, trunk_mask) -> Skeleton:
    """Algorithm 3, run once: every twig (the unbranched run from a tip up to its first ancestor with two or more
    children) longer, in edges, than floor(mean twig depth over the tips) is cut back to that depth. Tips with no
    branching ancestor do not count; trunk nodes are never removed (a trunk tip's twig is left whole). Leaves on
    removed nodes go with them; the rest keep their order (`Skeleton.subset`). trunk_mask : (N,) bool.
    """
    trunk = _check_mask(skeleton, trunk_mask, "trunk_mask")
    steps = _twig_steps(skeleton)
    depths = steps[skeleton.tips]
    depths = depths[depths >= 1]
    if len(depths) == 0:
        return skeleton
    average = int(np.floor(depths.mean()))
    # A node is on a twig when nothing below it branches; twig nodes deeper than the average go.
    branched_below = skeleton.n_children >= 2
    for level in depth_levels(skeleton.depth, tips_first=True):
        branched_below[skeleton.parent[level][branched_below[level]]] = True
    remove = ~branched_below & (steps > average) & ~trunk
    return skeleton.subset(~remove) if remove.any() else skeleton


# ------------------------------------------------------------------------------------------ gap filling
def _trunk_axis(skeleton: Skeleton, trunk: np.ndarray) -> np.ndarray:
    """(2,) float64, the trunk's mean horizontal position: the axis the crown's azimuths are measured around."""
    return skeleton.positions[trunk, :2].astype(np.float64).mean(axis=0)


def crown_sector_lengths(skeleton: Skeleton, trunk_mask, sectors: int = GAP_SECTORS) -> np.ndarray:
    """(sectors,) float64 metres of non-trunk branch per azimuth sector around the trunk axis; sector k spans
    [k, k + 1) * 360 / sectors degrees from +x toward +y, and an edge counts in the sector of its midpoint."""
    trunk = _check_mask(skeleton, trunk_mask, "trunk_mask")
    if isinstance(sectors, bool) or not isinstance(sectors, (int, np.integer)) or not 3 <= sectors <= 360:
        raise ParameterError("sectors", sectors, "an integer in [3, 360]")
    crown = np.flatnonzero(~trunk)
    crown = crown[crown > 0]
    middle = 0.5 * (skeleton.positions[crown, :2].astype(np.float64)
                    + skeleton.positions[skeleton.parent[crown], :2]) - _trunk_axis(skeleton, trunk)
    azimuth = np.mod(np.arctan2(middle[:, 1], middle[:, 0]), 2 * np.pi)
    sector = np.minimum((azimuth / (2 * np.pi) * sectors).astype(np.int64), sectors - 1)
    return np.bincount(sector, skeleton.segment_lengths[crown].astype(np.float64), sectors)


def _scan_is_sparse(reach: ScanReach, axis: np.ndarray, low: float, trunk_radius: float, start: int, count: int,
                    sectors: int, gap_ratio: float) -> bool:
    """Whether the scan's points above `low` and off the trunk (farther than twice `trunk_radius` from `axis`) in
    sectors start .. start + count - 1 number under `gap_ratio` of the median sector's: an occlusion gap, not a
    part of the crown the skeleton missed."""
    crown = reach.points[reach.points[:, 2] >= low, :2] - axis
    crown = crown[np.hypot(crown[:, 0], crown[:, 1]) > 2 * trunk_radius]
    azimuth = np.mod(np.arctan2(crown[:, 1], crown[:, 0]), 2 * np.pi)
    counts = np.bincount(np.minimum((azimuth / (2 * np.pi) * sectors).astype(np.int64), sectors - 1),
                         minlength=sectors)
    span = (start + np.arange(count)) % sectors
    return bool(counts[span].max(initial=0) < gap_ratio * np.median(counts))


def _gap_runs(lengths: np.ndarray, gap_ratio: float) -> list[tuple[int, int, float]]:
    """(first sector, sector count, missing metres) of each circular run of gap sectors, in sector order."""
    median = float(np.median(lengths))
    if median <= 0:  # most sectors are empty: a one-sided crown, not a crown with holes
        return []
    gap = lengths < gap_ratio * median
    if not gap.any():
        return []
    sectors = len(lengths)
    starts = np.flatnonzero(gap & ~np.roll(gap, 1))
    runs = []
    for start in starts.tolist():
        count = int(np.argmin(np.roll(gap, -start)))  # the first non-gap sector after the start
        span = (start + np.arange(count)) % sectors
        runs.append((start, count, float((median - lengths[span]).sum())))
    return runs


def _subtree_lengths(skeleton: Skeleton) -> np.ndarray:
    """(N,) float64 metres of edges below each node (its own parent edge excluded)."""
    below = np.zeros(len(skeleton))
    for level in depth_levels(skeleton.depth, tips_first=True):
        np.add.at(below, skeleton.parent[level], below[level] + skeleton.segment_lengths[level])
    return below


def fill_gaps(skeleton: Skeleton, rng: np.random.Generator, *, trunk_mask=None, sectors: int = GAP_SECTORS,
              gap_ratio: float = GAP_RATIO, degree_diff: float = DEGREE_DIFF,
              dist_diff_percent: float = DIST_DIFF_PERCENT, max_grafts_per_gap: int = MAX_GRAFTS_PER_GAP,
              pipe_exponent: float = 2.5, reach: ScanReach | None = None) -> Skeleton:
    """Graft noisy copies of the tree's own branches into the crown's azimuthal gaps (what occlusion leaves).

    A gap is a run of neighbouring sectors (`crown_sector_lengths`) with under `gap_ratio` of the median sector's
    branch length; none is filled when the median is 0 (a crown on one side is not a crown with holes). Per gap,
    ceil(missing length / mean donor length) grafts, at most `max_grafts_per_gap`, each:
    1. a donor: a branch growing out of the trunk, drawn by its length (`extract_subtree` of its first node);
    2. its noisy copy: `tree_to_lstring` -> `lstring_to_tree` (`lstring_round_trip`, the same tree without the
       text) with U(+-degree_diff) degrees on every angle and U(1 -+ dist_diff_percent) on every length, tips as
       thick as the donor's median tip;
    3. a side anchor (Algorithm 5) on a trunk node in the crown's height span whose first child is trunk, at an
       azimuth drawn inside the gap: the camera sits at up x gap direction, so the anchor's side, toCam x trunkDir,
       faces the gap (the digest's "toCam toward the gap" read so that the new branch grows into it);
    4. the graft (Algorithm 7) with pipe-rule radii (n = `pipe_exponent`) clamped to the anchor, and the anchor
       itself no thicker than the grafted branch it carries.
    trunk_mask : (N,) bool, default `identify_trunk`. reach : the scan's `ScanReach`; with it, a gap is grafted only
    where the scan's own points are as sparse (`_scan_is_sparse`), and grafted nodes outside the reach are cut
    (`keep_within_reach`). Returns the skeleton unchanged when there is no gap, no donor or no anchor node;
    otherwise the grafts are appended after the existing nodes.
    """
    trunk = identify_trunk(skeleton) if trunk_mask is None else _check_mask(skeleton, trunk_mask, "trunk_mask")
    if not 0 < gap_ratio < 1:
        raise ParameterError("gap_ratio", gap_ratio, "a share of the median sector's branch length in (0, 1)")
    if isinstance(max_grafts_per_gap, bool) or not isinstance(max_grafts_per_gap, (int, np.integer)) \
            or not 1 <= max_grafts_per_gap <= 100:
        raise ParameterError("max_grafts_per_gap", max_grafts_per_gap, "an integer in [1, 100]")
    runs = _gap_runs(crown_sector_lengths(skeleton, trunk, sectors), gap_ratio)
    if not runs:
        return skeleton
    node = np.arange(len(skeleton))
    donor_length = _subtree_lengths(skeleton)
    donors = node[(node > 0) & ~trunk & trunk[np.maximum(skeleton.parent, 0)] & (donor_length > 0)]
    first_child = np.full(len(skeleton), len(skeleton), np.int64)  # side_anchor follows a node's first child
    np.minimum.at(first_child, skeleton.parent[1:], node[1:])
    z = skeleton.positions[:, 2]
    has_child = first_child < len(skeleton)
    anchors = node[trunk & has_child & trunk[np.where(has_child, first_child, 0)]]
    if len(donors):
        low, high = z[skeleton.parent[donors]].min(), z[trunk].max()
        anchors = anchors[(z[anchors] >= low) & (z[anchors] <= high)]
    if len(donors) == 0 or len(anchors) == 0:
        return skeleton
    weights = donor_length[donors] / donor_length[donors].sum()
    mean_donor = float(donor_length[donors].mean())
    width = 2 * np.pi / sectors
    camera_distance = 2.0 * max(skeleton.crown_radius, 1.0)
    grown = skeleton
    if reach is not None:
        axis, crown_low = _trunk_axis(skeleton, trunk), float(z[skeleton.parent[donors]].min())
        trunk_radius = float(skeleton.radius[trunk].max())
        runs = [run for run in runs
                if _scan_is_sparse(reach, axis, crown_low, trunk_radius, run[0], run[1], sectors, gap_ratio)]
    for start, count, missing in runs:
        n_grafts = int(min(max_grafts_per_gap, max(1, np.ceil(missing / mean_donor))))
        for _ in range(n_grafts):
            donor = extract_subtree(skeleton, int(rng.choice(donors, p=weights)))
            tip_radius = float(np.median(donor.radius[donor.tips]))
            copy = lstring_round_trip(donor, rng, degree_diff, dist_diff_percent, tip_radius=tip_radius,
                                      pipe_exponent=pipe_exponent)
            azimuth = (start + rng.uniform(0.15, 0.85) * count) * width
            toward_gap = np.array([np.cos(azimuth), np.sin(azimuth), 0.0])
            at = int(rng.choice(anchors))
            camera = skeleton.positions[at] + camera_distance * np.cross([0.0, 0.0, 1.0], toward_gap)
            grown, anchor = side_anchor(grown, at, camera, right=True)
            grown = graft(grown, anchor, copy, smoothing="pipe", pipe_exponent=pipe_exponent)
            radius = grown.radius.copy()
            carried = radius[anchor + 1:][grown.parent[anchor + 1:] == anchor].astype(np.float64)
            radius[anchor] = min(radius[anchor], (carried ** pipe_exponent).sum() ** (1 / pipe_exponent))
            grown = Skeleton(positions=grown.positions, parent=grown.parent, radius=radius, order=grown.order,
                             leaves=grown.leaves, leaf_node=grown.leaf_node)
    return grown if reach is None else keep_within_reach(grown, reach, len(skeleton))


# ------------------------------------------------------------------------------------------- the chain
def complete(skeleton: Skeleton, rng: np.random.Generator, *, twigs: str | None = "alternate", prune: bool = True,
             fill: bool = True, radius_threshold: float = RADIUS_THRESHOLD,
             degree_threshold: float = DEGREE_THRESHOLD, reach: ScanReach | None = None) -> Skeleton:
    """Seed 003's editing chain on a measured skeleton, ready for `build_mesh`:

    1. `identify_trunk` (Algorithm 2), and orders made to agree with it (trunk 0, every other node >= 1, so the
       QSM outputs' branch 0 is this trunk);
    2. `prune_long_twigs` (Algorithm 3) when `prune`;
    3. `fill_gaps` (Algorithms 4-8) when `fill`;
    4. `add_twigs` with the phyllotaxis pattern `twigs` (a `PATTERNS` name: opposite, alternate, whorled) at every
       tip, a leaf card on each terminal F; None adds no twigs and no leaves.
    With `reach` (the scan's `ScanReach`), grafts go only into the scan's own gaps, and every node and leaf card
    added by steps 3-4 outside the reach is cut (`keep_within_reach`). Pruning removes measured twigs: a
    measured skeleton is completed with `prune=False`, which removes nothing.
    """
    if twigs is not None and twigs not in PATTERNS:
        raise ParameterError("twigs", twigs, f"one of {sorted(PATTERNS)} or None")
    trunk = identify_trunk(skeleton, radius_threshold, degree_threshold)
    edited = _with_trunk_orders(skeleton, trunk)
    if prune:
        edited = prune_long_twigs(edited, edited.order == 0)
    first_added = len(edited)
    if fill:
        edited = fill_gaps(edited, rng, trunk_mask=edited.order == 0, reach=reach)
    if twigs is not None:
        edited = add_twigs(edited, twigs, rng)
    return edited if reach is None else keep_within_reach(edited, reach, first_added)
