"""Levels of detail built from the skeleton, as a tree artist would: fewer sides, fewer rings, short twigs
dropped (their leaves handed to the parent branch), leaves merged into larger crossed cluster cards.

In: a Skeleton, its LOD0 TreeMesh and a triangle budget (fraction of LOD0). Out: a `LodLevel` (simplified
skeleton whose `leaves` are the cluster cards, its TreeMesh, and which original node each kept node was).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import TreefarmError
from .mesh import DEFAULT_RADIAL_SEGMENTS, bark_part, leaf_part
from .polyline_simplify import simplification_keys
from .skeleton import LEAF_CARD_CORNERS, Skeleton
from .tree_mesh import TreeMesh

__all__ = ["LodLevel", "LodBudgetError", "build_lod", "simplify_skeleton", "cluster_leaves", "metres_per_pixel",
           "nearest_kept_ancestor", "LOD_SIDES", "LOD_NODE_STEPS", "LOD_SWITCH_PX", "TOLERANCE_LADDER_PX",
           "CARDS_PER_CLUSTER"]

# Tube sides by branch order at each level (index = level - 1): the trunk keeps the most.
LOD_SIDES = ((6, 4, 3), (5, 3, 3), (4, 3, 3))
# Default switch sizes (pixels of tree size on screen) the levels are simplified for.
LOD_SWITCH_PX = (512, 256, 128)
# Screen tolerances (pixels at the switch size) tried for the bark, finest first.
TOLERANCE_LADDER_PX = tuple(0.1 * 1.25 ** np.arange(60))
# Branches shorter than this many tolerances are dropped (their leaves move to the parent branch).
DROP_LENGTH_TOLERANCES = 2.0
# Branches at least this wide on screen (pixels) keep their axis within THICK_TOLERANCE_PX pixels.
THICK_BRANCH_PX = 2.0
THICK_TOLERANCE_PX = 1.0
# Fallback only (budgets too small for the tolerance ladder): keep every n-th node along a branch by level.
LOD_NODE_STEPS = (2, 3, 4)
_MAX_NODE_STEP = 32
# A cluster is drawn as one card (2 triangles).
CARDS_PER_CLUSTER = 1
# Shares of the longest branch below which branches are dropped, tried in turn until the bark fits its budget.
_PRUNE_LADDER = (0.0, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3, 0.4, 0.55, 0.7, 0.85, 1.01)
# The budget is filled to this fraction at most: merging of close rings can only lower counts, never raise.
_BUDGET_MARGIN = 0.97
# Span of a uniform spread in standard deviations: a cluster card reaches as far as its leaves do.
_SPREAD_SPAN = 2.0 * np.sqrt(3.0)
# A cluster card covers this many times its leaves' estimated covered area (within their spread): from afar the
# gaps between a cluster's leaves close, so its outline is more than its leaf area (measured: 1.5 raises the
# LOD1/LOD2 min IoU of maple .899 -> .911 / .866 -> .880 and pine .885 -> .896 / .856 -> .882; 2.5 overshoots).
_CLUSTER_AREA_GAIN = 1.5

class LodBudgetError(TreefarmError):
    """A level of detail cannot meet its triangle budget (the budget is too small for this tree)."""


@dataclass(frozen=True)
class LodLevel:
    """One level of detail.

    level         : 1, 2, 3, ...
    skeleton      : the simplified skeleton; its leaves are the cluster cards (CARDS_PER_CLUSTER per cluster).
    mesh          : its TreeMesh (bark with `order`/`branch`, cards with `node` attributes).
    original_node : (N',) int32, the LOD0 node each kept node is.
    n_clusters    : leaf clusters (cards / CARDS_PER_CLUSTER).
    """

    level: int
    skeleton: Skeleton
    mesh: TreeMesh
    original_node: np.ndarray
    n_clusters: int

    @property
    def n_triangles(self) -> int:
        return self.mesh.n_faces


def nearest_kept_ancestor(parent: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """(N,) int64: for each node, itself if kept, else its nearest kept ancestor (-1 if none).

    parent : (N,) int, -1 at the root; keep : (N,) bool. Pointer jumping, vectorised.
    """
    parent = np.asarray(parent, np.int64)
    anchor = np.where(keep, np.arange(len(parent)), parent)
    while True:
        unresolved = (anchor >= 0) & ~keep[np.maximum(anchor, 0)]
        if not unresolved.any():
            return anchor
        anchor = np.where(unresolved, parent[np.maximum(anchor, 0)], anchor)


def _branch_lengths(skeleton: Skeleton) -> np.ndarray:
    """(B,) float64 metres of each branch (its own segments, the one from its junction included)."""
    return np.bincount(skeleton.branch_id, weights=skeleton.segment_lengths.astype(np.float64),
                       minlength=skeleton.n_branches)


def _branch_parent(skeleton: Skeleton) -> np.ndarray:
    """(B,) int64, the branch each branch grows from (-1 for the trunk)."""
    starts = skeleton.branch_starts
    junction = skeleton.parent[starts]
    return np.where(junction >= 0, skeleton.branch_id[np.maximum(junction, 0)], -1).astype(np.int64)


def _droppable(skeleton: Skeleton, clones: bool) -> tuple[np.ndarray, np.ndarray]:
    """(B,) float64 metres of each branch and (B,) bool, the branches pruning may drop: non-trunk ones (with
    `clones`, the trunk's split clones too: every branch but branch 0)."""
    order = skeleton.order[skeleton.branch_starts]
    return _branch_lengths(skeleton), (order > 0) | (clones & (np.arange(len(order)) > 0))


def _dropped_branches(skeleton: Skeleton, min_length: float, max_order: int | None = None,
                      clones: bool = False) -> np.ndarray:
    """(B,) bool: droppable branches (see `_droppable`) shorter than `min_length` metres, branches above
    `max_order`, and everything on them."""
    lengths, candidate = _droppable(skeleton, clones)
    drop = candidate & (lengths < min_length)
    if max_order is not None:
        drop |= skeleton.order[skeleton.branch_starts] > max_order
    parent = _branch_parent(skeleton)
    while True:
        inherited = drop | ((parent >= 0) & drop[np.maximum(parent, 0)])
        if np.array_equal(inherited, drop):
            return drop
        drop = inherited


def _longest_candidate(skeleton: Skeleton, clones: bool) -> float:
    """Metres, the longest branch that pruning may drop (see `_droppable`)."""
    lengths, candidate = _droppable(skeleton, clones)
    return float(lengths[candidate].max()) if candidate.any() else 0.0


def _keep_mask(skeleton: Skeleton, share: float, node_step: int, max_order: int | None = None,
               clones: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool nodes kept and (B,) bool branches dropped, for a pruning share (of the longest droppable
    branch) and node step (and the fallbacks of `_dropped_branches`)."""
    drop = _dropped_branches(skeleton, share * _longest_candidate(skeleton, clones), max_order, clones)
    starts = skeleton.branch_starts
    along = skeleton.depth - skeleton.depth[starts][skeleton.branch_id]
    every_nth = (along % node_step == 0) | (skeleton.continuation < 0)  # every n-th node and the tip
    return _with_structure(skeleton, every_nth, drop), drop


def _with_structure(skeleton: Skeleton, chosen: np.ndarray, drop: np.ndarray) -> np.ndarray:
    """(N,) bool: the `chosen` nodes of branches not dropped, plus what keeps the branching intact: the root,
    each kept branch's first node and the node it grows from."""
    keep = chosen & ~drop[skeleton.branch_id]
    starts = skeleton.branch_starts[~drop]
    keep[starts] = True
    junctions = skeleton.parent[starts]
    keep[junctions[junctions >= 0]] = True
    keep[0] = True
    return keep


def _node_keys(skeleton: Skeleton) -> np.ndarray:
    """(N,) float64 metres, each node's Douglas-Peucker key along its own branch (see `simplification_keys`);
    a branch's path starts at its junction on the parent, so the junction bounds the first chord."""
    paths = skeleton.branch_paths
    nodes = np.concatenate(paths).astype(np.int64)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in paths])])
    keys = simplification_keys(skeleton.positions[nodes], skeleton.radius[nodes], offsets)
    own = skeleton.branch_id[nodes] == np.repeat(np.arange(len(paths)), np.diff(offsets))
    node_keys = np.full(len(skeleton), np.inf)
    node_keys[nodes[own]] = keys[own]
    return node_keys


def _tolerance_mask(skeleton: Skeleton, node_keys: np.ndarray, tolerance: float,
                    metres_per_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool nodes kept and (B,) bool branches dropped at a tolerance in metres: branches shorter than
    DROP_LENGTH_TOLERANCES tolerances go (with all on them), the others keep the nodes Douglas-Peucker needs
    to stay within the tolerance of their axis and radius. Branches at least THICK_BRANCH_PX wide on screen
    stay within THICK_TOLERANCE_PX whatever the tolerance: a thin branch moved off its line costs its own
    width in silhouette however far it moves, a thick one costs the whole offset along its length."""
    drop = _dropped_branches(skeleton, DROP_LENGTH_TOLERANCES * tolerance)
    diameter = 2.0 * skeleton.radius[skeleton.branch_starts].astype(np.float64)
    thick = diameter >= THICK_BRANCH_PX * metres_per_px
    limit = np.where(thick, min(tolerance, THICK_TOLERANCE_PX * metres_per_px), tolerance)
    return _with_structure(skeleton, node_keys > limit[skeleton.branch_id], drop), drop


def simplify_skeleton(skeleton: Skeleton, share: float, node_step: int) -> tuple[Skeleton, np.ndarray, np.ndarray]:
    """Drop branches shorter than `share` of the longest branch and keep every `node_step`-th node.

    Returns (skeleton without leaves, original_node (N',) int64, leaf_anchor (M,) int64 new node index of each
    original leaf's nearest kept ancestor). Branch first nodes, tips and junctions of kept branches stay.
    """
    keep, _ = _keep_mask(skeleton, share, node_step)
    return _skeleton_from_mask(skeleton, keep)


def _skeleton_from_mask(skeleton: Skeleton, keep: np.ndarray) -> tuple[Skeleton, np.ndarray, np.ndarray]:
    anchor = nearest_kept_ancestor(skeleton.parent, keep)
    original = np.flatnonzero(keep)
    new_index = np.full(len(skeleton), -1, np.int64)
    new_index[original] = np.arange(len(original))
    parent = np.full(len(original), -1, np.int64)
    parent[1:] = new_index[anchor[np.maximum(skeleton.parent[original[1:]], 0)]]
    simplified = Skeleton(skeleton.positions[original], parent, skeleton.radius[original],
                          skeleton.order[original])
    leaf_anchor = new_index[anchor[skeleton.leaf_node]] if skeleton.n_leaves else np.zeros(0, np.int64)
    return simplified, original.astype(np.int64), leaf_anchor


def _bark_triangle_estimate(skeleton: Skeleton, keep: np.ndarray, drop: np.ndarray, sides_by_order) -> int:
    """Upper bound of `bark_part` triangles of the kept nodes: 2 S per ring gap, S per tip cone, S for the
    root disc (branch ids of the original skeleton; kept branches keep their identity)."""
    counts = np.bincount(skeleton.branch_id[keep], minlength=skeleton.n_branches) + 1  # + junction point
    counts[0] -= 1  # the trunk has no junction
    order = skeleton.order[skeleton.branch_starts]
    table = np.asarray(sides_by_order, np.int64)
    sides = table[np.minimum(order, len(table) - 1)]
    meshed = (counts >= 2) & ~drop
    return int((sides * (2 * (counts - 1) + 1))[meshed].sum() + sides[0])


def cluster_leaves(leaves: np.ndarray, anchor: np.ndarray, n_clusters: int) -> tuple[np.ndarray, np.ndarray]:
    """Merge leaves into at most `n_clusters` larger cards on a voxel grid (one card per occupied cell).

    leaves : (M, 4, 4) float, each leaf's transform of the unit card; anchor : (M,) int, node of each leaf.
    Returns (transforms (C, 4, 4) float32, card_node (C,) int32). A cluster's card takes the orientation and
    node of its leaf nearest the cluster centre, is centred on the cluster, and is scaled so its area is the
    area the members cover together: sum of areas x (1 - exp(-d)) / d, with d their projected area (half
    their area, random orientation) over the cell's face. A cluster of one leaf is that leaf.
    """
    leaves = np.asarray(leaves, np.float64)
    m = len(leaves)
    if m == 0 or n_clusters <= 0:
        return np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32)
    homo = np.concatenate([LEAF_CARD_CORNERS, np.ones((4, 1), np.float32)], axis=1).astype(np.float64)
    corners = np.einsum("mij,kj->mki", leaves, homo)[..., :3]
    centres = corners.mean(axis=1)
    labels, cell = _grid_labels(centres, min(n_clusters, m))
    n = int(labels.max()) + 1
    count = np.bincount(labels, minlength=n)
    mid = np.stack([np.bincount(labels, weights=centres[:, k], minlength=n) for k in range(3)], axis=1)
    mid /= count[:, None]
    # Representative: the member nearest its cluster centre (lowest index on ties).
    distance = np.linalg.norm(centres - mid[labels], axis=1)
    order = np.lexsort((np.arange(m), distance, labels))
    first = np.ones(m, bool)
    first[1:] = labels[order][1:] != labels[order][:-1]
    representative = order[first]
    areas = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0]), axis=1)
    total = np.bincount(labels, weights=areas, minlength=n)
    d = 0.5 * total / (cell * cell)
    covered = np.where(count > 1, total * -np.expm1(-d) / np.maximum(d, 1e-12), total)
    cards = leaves[representative].copy()
    merged = count[labels] > 1
    if merged.any():
        fitted = _fitted_cards(corners[merged].reshape(-1, 3), np.repeat(labels[merged], 4), n, covered)
        many = count > 1
        cards[many] = fitted[many]
    card_node = np.asarray(anchor)[representative]
    return cards.astype(np.float32), card_node.astype(np.int32)


def _fitted_cards(points: np.ndarray, labels: np.ndarray, n: int, area: np.ndarray) -> np.ndarray:
    """(n, 4, 4) float64 card transforms fitted to each cluster's points (P, 3) metres (labels (P,) int in
    [0, n)): centred on the points' mean, length along their principal axis, width along the second, normal
    along the least spread; length and width span the points as a uniform spread would (2 sqrt(3) std)."""
    count = np.maximum(np.bincount(labels, minlength=n), 1).astype(np.float64)
    mean = np.stack([np.bincount(labels, weights=points[:, k], minlength=n) for k in range(3)], axis=1)
    mean /= count[:, None]
    rel = points - mean[labels]
    outer = (rel[:, :, None] * rel[:, None, :]).reshape(-1, 9)
    cov = np.stack([np.bincount(labels, weights=outer[:, k], minlength=n) for k in range(9)], axis=1)
    cov = cov.reshape(n, 3, 3) / count[:, None, None]
    variance, axes = np.linalg.eigh(cov)  # ascending: axes[:, :, 2] the principal axis
    span = _SPREAD_SPAN * np.sqrt(np.maximum(variance, 0.0))
    length, width = np.maximum(span[:, 2], 1e-4), np.maximum(span[:, 1], 1e-4)
    # The card's area is the area the leaves cover (`area`, x _CLUSTER_AREA_GAIN), in the spread's proportions,
    # never beyond the spread.
    shrink = np.minimum(np.sqrt(_CLUSTER_AREA_GAIN * area / (length * width)), 1.0)
    length, width = length * shrink, width * shrink
    along, across, normal = axes[:, :, 2], axes[:, :, 1], axes[:, :, 0]
    # Right-handed (width, normal, length) as the unit card's (x, y, z).
    flip = np.einsum("ci,ci->c", np.cross(across, normal), along) < 0
    normal = np.where(flip[:, None], -normal, normal)
    cards = np.zeros((n, 4, 4))
    cards[:, :3, 0] = across * width[:, None]
    cards[:, :3, 1] = normal * width[:, None]
    cards[:, :3, 2] = along * length[:, None]
    cards[:, :3, 3] = mean - 0.5 * cards[:, :3, 2]
    cards[:, 3, 3] = 1.0
    return cards


def _grid_labels(points: np.ndarray, target: int) -> np.ndarray:
    """(M,) int64 cluster label per point (occupied cells of the finest cubic grid with at most `target` cells,
    by bisection on the cell size, numbered in sorted cell order) and the cell size in metres."""
    lo = points.min(axis=0)
    span = float(np.max(points.max(axis=0) - lo)) + 1e-9
    # Counting cells is a hash of the keys (no sort): every point up to this many, a regular sample beyond.
    sample = points if len(points) <= 200_000 else points[:: len(points) // 200_000 + 1]

    def cell_keys(size: float, pts: np.ndarray) -> np.ndarray:
        keys = np.floor((pts - lo) / size).astype(np.int64)
        return keys[:, 0] * 4_000_037 ** 2 + keys[:, 1] * 4_000_037 + keys[:, 2]

    small, large = span / 4096, span * 1.01
    for _ in range(24):
        size = np.sqrt(small * large)
        if len(np.unique(cell_keys(size, sample))) >= target:
            small = size
        else:
            large = size
        if large / small < 1.02:
            break
    size = large  # the finest grid with at most `target` cells (on the sample; checked on all points)
    keys = cell_keys(size, points)
    while len(np.unique(keys)) > target:
        size *= 1.05
        keys = cell_keys(size, points)
    _, labels = np.unique(keys, return_inverse=True)
    return labels.astype(np.int64), size


def _fit_bark(skeleton: Skeleton, sides, bark_target: int, first_step: int, max_step: int, variants):
    """The first (simplified skeleton, original_node, leaf_anchor) whose bark estimate fits `bark_target`,
    trying node steps from `first_step` doubling up to `max_step`, each with the prune ladder under each
    (max_order, clones) variant; None when nothing fits."""
    step = first_step
    while True:
        for max_order, clones in variants:
            for share in _PRUNE_LADDER:
                keep, drop = _keep_mask(skeleton, share, step, max_order, clones)
                if _bark_triangle_estimate(skeleton, keep, drop, sides) <= bark_target:
                    return _skeleton_from_mask(skeleton, keep)
        if step >= max_step:
            return None
        step = min(2 * step, max_step)


def _widened(skeleton: Skeleton, sides_by_order) -> Skeleton:
    """The skeleton with each node's radius raised so an S-sided tube shows, on average over view directions,
    the width LOD0's tube of that order shows: a convex outline's mean width is its perimeter / pi, so an
    S-gon of circumradius R shows 2 R S sin(pi / S) / pi (LOD0 sides: DEFAULT_RADIAL_SEGMENTS)."""
    def mean_width(sides):
        return sides * np.sin(np.pi / sides)

    order = np.asarray(skeleton.order, np.int64)
    table = np.asarray(sides_by_order, np.float64)
    lod0_table = np.asarray(DEFAULT_RADIAL_SEGMENTS, np.float64)
    widen = (mean_width(lod0_table[np.minimum(order, len(lod0_table) - 1)])
             / mean_width(table[np.minimum(order, len(table) - 1)]))
    return Skeleton(skeleton.positions, skeleton.parent, (skeleton.radius * np.maximum(widen, 1.0)).astype(np.float32),
                    skeleton.order)


def _fit_bark_by_tolerance(skeleton: Skeleton, sides, bark_target: int, metres_per_px: float):
    """The (simplified skeleton, original_node, leaf_anchor) of the smallest screen tolerance on
    TOLERANCE_LADDER_PX (pixels of `metres_per_px` metres) whose bark estimate fits `bark_target`, by
    bisection (coarser tolerances never keep more); None when even the coarsest does not fit."""
    keys = _node_keys(skeleton)

    def fits(step: int):
        keep, drop = _tolerance_mask(skeleton, keys, TOLERANCE_LADDER_PX[step] * metres_per_px, metres_per_px)
        return keep if _bark_triangle_estimate(skeleton, keep, drop, sides) <= bark_target else None

    lo, hi = 0, len(TOLERANCE_LADDER_PX) - 1
    best = fits(hi)
    if best is None:
        return None
    if (first := fits(lo)) is not None:
        return _skeleton_from_mask(skeleton, first)
    while hi - lo > 1:  # fits(hi) holds, fits(lo) does not
        mid = (lo + hi) // 2
        keep = fits(mid)
        if keep is None:
            lo = mid
        else:
            hi, best = mid, keep
    return _skeleton_from_mask(skeleton, best)


def metres_per_pixel(skeleton: Skeleton, switch_px: int) -> float:
    """Metres a screen pixel spans when the tree's larger extent (height or width) is `switch_px` pixels."""
    lo, hi = np.asarray(skeleton.bounds, np.float64)
    return max(float(np.max(hi - lo)), 1e-6) / switch_px


def build_lod(skeleton: Skeleton, lod0: TreeMesh, level: int, budget: float, switch_px: int | None = None) -> LodLevel:
    """Level `level` (1..3) of detail within `budget` (fraction of LOD0 triangles), for viewing at `switch_px`
    pixels of tree size (default LOD_SWITCH_PX[level - 1]).

    The bark keeps its LOD0 share of the budget: each branch keeps the nodes Douglas-Peucker needs to stay
    within a screen tolerance of its axis and radius, branches a few tolerances long are dropped, and the
    tolerance is the smallest of the ladder that fits. The leaves get the rest of the budget as cluster
    cards. Raises LodBudgetError when nothing fits.
    """
    if not 1 <= level <= len(LOD_SIDES):
        raise LodBudgetError(f"level {level} is unknown: allowed 1..{len(LOD_SIDES)}")
    if not 0.0 < budget <= 1.0:
        raise LodBudgetError(f"budget {budget!r} for LOD{level} is invalid: allowed a fraction in (0, 1]")
    switch_px = LOD_SWITCH_PX[level - 1] if switch_px is None else switch_px
    if isinstance(switch_px, bool) or not isinstance(switch_px, (int, np.integer)) or not 8 <= switch_px <= 4096:
        raise LodBudgetError(f"switch size {switch_px!r} px for LOD{level} is invalid: allowed an integer in "
                             f"[8, 4096]")
    total0 = lod0.n_faces
    target = int(np.floor(_BUDGET_MARGIN * budget * total0))
    bark_share = lod0.bark.n_faces / max(total0, 1)
    sides = LOD_SIDES[level - 1]
    leaf_tris_per_cluster = 2 * CARDS_PER_CLUSTER
    min_leaf_tris = leaf_tris_per_cluster if skeleton.n_leaves else 0
    bark_target = max(int(target * bark_share), 0)
    if skeleton.n_leaves:
        bark_target = min(bark_target, target - min_leaf_tris)
    chosen = _fit_bark_by_tolerance(skeleton, sides, bark_target, metres_per_pixel(skeleton, int(switch_px)))
    if chosen is None:
        # Fallback, as an artist would for a far tree: 3-sided tubes, the bark may take all but one card's
        # share, nodes thinned down to branch ends, first-order branches only, then the trunk's split clones
        # pruned like branches; the leaves go into the few cluster cards left.
        sides = (3,) * len(sides)
        bark_target = target - min_leaf_tris
        chosen = _fit_bark(skeleton, sides, bark_target, LOD_NODE_STEPS[level - 1],
                           max(_MAX_NODE_STEP, int(skeleton.depth.max()) + 1), ((1, False), (1, True)))
    if chosen is None:
        raise LodBudgetError(f"LOD{level} budget {budget:.3f} x {total0} LOD0 triangles = {target} leaves no "
                             f"room for the trunk alone; raise the LOD{level} budget")
    simplified, original, leaf_anchor = chosen
    simplified = _widened(simplified, sides)
    bark = bark_part(simplified, sides, 3, thick_more=False)
    leaf_budget = target - bark.n_faces
    n_clusters = leaf_budget // leaf_tris_per_cluster if skeleton.n_leaves else 0
    if skeleton.n_leaves and n_clusters < 1:
        raise LodBudgetError(f"LOD{level} budget {budget:.3f} leaves no room for a leaf card "
                             f"({bark.n_faces} bark triangles of {target}); raise the LOD{level} budget")
    cards, card_node = cluster_leaves(skeleton.leaves, leaf_anchor, int(n_clusters))
    lod_skeleton = Skeleton(simplified.positions, simplified.parent, simplified.radius, simplified.order,
                            leaves=cards, leaf_node=card_node)
    mesh = TreeMesh(bark=bark, leaves=leaf_part(lod_skeleton), bark_color=lod0.bark_color,
                    leaf_color=lod0.leaf_color, name=f"{lod0.name}_LOD{level}")
    return LodLevel(level, lod_skeleton, mesh, original.astype(np.int32), len(cards) // CARDS_PER_CLUSTER)
