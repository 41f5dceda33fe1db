"""Levels of detail built from the skeleton, as a tree artist would: fewer sides, fewer rings, short twigs
dropped (their leaves handed to the parent branch), leaves merged into larger cluster cards.

In: a Skeleton, its LOD0 TreeMesh and a triangle budget (fraction of LOD0). Out: a `LodLevel` (simplified
skeleton whose `leaves` are the cluster cards, its TreeMesh, and which original node each kept node was).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..errors import TreefarmError
from ..meshing.tubes_and_cards import CARD_FACES, DEFAULT_RADIAL_SEGMENTS, bark_part, leaf_part
from .leaf_clusters import CLUSTER_AREA_GAIN, LeafCards
from .twig_cards import TWIG_CARD_PLANES, TwigCards, twig_cards, twig_labels
from ..geometry.polyline_simplify import simplification_keys
from ..geometry.topology import depth_levels, node_depths
from ..skeleton import Skeleton
from ..tree_mesh import MeshPart, TreeMesh

__all__ = ["LodLevel", "LodBudgetError", "TreeLods", "build_lod", "simplify_skeleton", "metres_per_pixel",
           "nearest_kept_ancestor", "LOD_SIDES", "LOD_NODE_STEPS", "LOD_SWITCH_PX", "TOLERANCE_LADDER_PX",
           "CLUMP_ATTRIBUTE", "card_clumps", "subtree_maximum", "branch_node_keys"]

# Tube sides by branch order at each level (index = level - 1): the trunk keeps the most.
LOD_SIDES = ((6, 4, 3), (5, 3, 3), (4, 3, 3))
# Default switch sizes (pixels of tree size on screen) the levels are simplified for.
LOD_SWITCH_PX = (512, 256, 128)
# Screen tolerances (pixels at the switch size) tried for the bark, finest first.
TOLERANCE_LADDER_PX = tuple(0.1 * 1.25 ** np.arange(60))
# The tolerances weighed against dropping branches: the ladder up to this many pixels.
_MAX_WEIGHED_TOLERANCE_PX = 16.0
# Branches at least this wide on screen (pixels) keep their axis within THICK_TOLERANCE_PX pixels, their sides by
# order and their tip cones; thinner ones are bare 3-sided tubes (their cone and extra sides show nothing).
THICK_BRANCH_PX = 2.0
THICK_TOLERANCE_PX = 1.0
# Fallback only (budgets too small for the tolerance ladder): keep every n-th node along a branch by level.
LOD_NODE_STEPS = (2, 3, 4)
_MAX_NODE_STEP = 32
# A cluster is drawn as one card: its triangles.
_CARD_TRIANGLES = len(CARD_FACES)
# Per-vertex leaf attribute of LOD meshes: 1 where a card merges several leaves (textured as a clump), 0 where it
# is one leaf (textured as that leaf); LOD0's cards have none (every card is one leaf).
CLUMP_ATTRIBUTE = "clump"
# Shares of the longest branch below which branches are dropped, tried in turn until the bark fits its budget.
_PRUNE_LADDER = (0.0, 0.03, 0.06, 0.1, 0.15, 0.2, 0.3, 0.4, 0.55, 0.7, 0.85, 1.01)
# How deep a dropped subtree splits into twig cards, tried in turn until the cards fit (None: a card per branch).
TWIG_DEPTHS = (None, 3, 2, 1, 0)
# The budget is filled to this fraction at most: merging of close rings can only lower counts, never raise.
_BUDGET_MARGIN = 0.97

class LodBudgetError(TreefarmError):
    """A level of detail cannot meet its triangle budget (the budget is too small for this tree)."""


@dataclass(frozen=True)
class LodLevel:
    """One level of detail.

    level         : 1, 2, 3, ...
    skeleton      : the simplified skeleton; its leaves are the cluster cards (one per cluster).
    mesh          : its TreeMesh (bark with `order`/`branch`, cards with `node` and `clump` attributes; `clump` is
                    1 on the vertices of cards that merge several leaves, 0 on cards that are one leaf).
    original_node : (N',) int32, the LOD0 node each kept node is.
    n_clusters    : leaf clusters (one card each).
    twigs         : the twig cluster cards drawing the branches this level drops (with their leaves), or None
                    (dropped branches' leaves then go to the cluster cards); not part of `mesh`, which holds
                    the tubes and leaf cards.
    """

    level: int
    skeleton: Skeleton
    mesh: TreeMesh
    original_node: np.ndarray
    n_clusters: int
    twigs: TwigCards | None = None

    @property
    def n_triangles(self) -> int:
        return self.mesh.n_faces + _CARD_TRIANGLES * (len(self.twigs) if self.twigs is not None else 0)


def card_clumps(leaves: MeshPart) -> np.ndarray:
    """(C,) bool per card of a leaf MeshPart (four vertices per card): True where the card merges several leaves
    (CLUMP_ATTRIBUTE), all False for cards without that attribute (LOD0's)."""
    flags = leaves.attributes.get(CLUMP_ATTRIBUTE)
    if flags is None:
        return np.zeros(leaves.n_vertices // 4, bool)
    return np.asarray(flags[::4]) > 0


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
    parent = skeleton.branch_parent
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


def branch_node_keys(skeleton: Skeleton) -> np.ndarray:
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
    """Upper bound of `bark_part` triangles of the kept nodes with sides by order and every tip coned: 2 S per
    ring gap, S per tip cone, S for the root disc (branch ids of the original skeleton; kept branches keep
    their identity)."""
    order = skeleton.order[skeleton.branch_starts]
    table = np.asarray(sides_by_order, np.int64)
    sides = table[np.minimum(order, len(table) - 1)]
    costs = _branch_triangles(skeleton, keep, sides, np.ones(len(sides), bool))
    return int(costs[~drop].sum())


def _branch_triangles(skeleton: Skeleton, keep: np.ndarray, sides: np.ndarray, coned: np.ndarray) -> np.ndarray:
    """(B,) int64 upper bound of each branch's `bark_part` triangles from its kept nodes (its junction node
    counts as its first ring): 2 S per ring gap, S for a tip cone, S for the root disc; 0 for a branch with
    fewer than two rings."""
    counts = np.bincount(skeleton.branch_id[keep], minlength=skeleton.n_branches) + 1  # + junction point
    counts[0] -= 1  # the trunk has no junction
    costs = sides * (2 * (counts - 1) + coned)
    costs[0] += sides[0]
    return np.where(counts >= 2, costs, 0)


def _fit_bark_by_steps(skeleton: Skeleton, sides, bark_target: int, first_step: int, max_step: int, variants):
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


def _widened(skeleton: Skeleton, branch_sides: np.ndarray) -> Skeleton:
    """The skeleton with each node's radius raised so an S-sided tube (branch_sides (B,) int per branch) shows, on
    average over view directions, the width LOD0's tube of that order shows: a convex outline's mean width is
    its perimeter / pi, so an S-gon of circumradius R shows 2 R S sin(pi / S) / pi (LOD0 sides:
    DEFAULT_RADIAL_SEGMENTS)."""
    def mean_width(sides):
        return sides * np.sin(np.pi / sides)

    order = np.asarray(skeleton.order, np.int64)
    lod0_table = np.asarray(DEFAULT_RADIAL_SEGMENTS, np.float64)
    sides = np.asarray(branch_sides, np.float64)[skeleton.branch_id]
    widen = mean_width(lod0_table[np.minimum(order, len(lod0_table) - 1)]) / mean_width(sides)
    return Skeleton(skeleton.positions, skeleton.parent, (skeleton.radius * np.maximum(widen, 1.0)).astype(np.float32),
                    skeleton.order)


def _branch_sides(skeleton: Skeleton, sides_by_order, metres_per_px: float) -> tuple[np.ndarray, np.ndarray]:
    """(B,) int64 sides and (B,) bool tip cones per branch: by order for branches at least THICK_BRANCH_PX wide
    on screen where they start, 3 sides and no cone for thinner ones."""
    starts = skeleton.branch_starts
    table = np.asarray(sides_by_order, np.int64)
    thick = 2.0 * skeleton.radius[starts].astype(np.float64) >= THICK_BRANCH_PX * metres_per_px
    sides = np.where(thick, table[np.minimum(skeleton.order[starts], len(table) - 1)], 3)
    return sides.astype(np.int64), thick


def subtree_maximum(value: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """(B,) float64: the largest value in each branch's subtree (itself and every branch growing from it, parent
    (B,) int, -1 at the root), so ranking by it puts a branch before everything on it: keeping the largest
    first never keeps a branch without the one it grows from, nor drops a stub that carries a long limb."""
    value = np.asarray(value, np.float64).copy()
    parent = np.asarray(parent, np.int64)
    for at in depth_levels(node_depths(parent), tips_first=True):  # one pass per branching depth
        np.maximum.at(value, parent[at], value[at])
    return value


def _fit_bark_by_tolerance(skeleton: Skeleton, keys: np.ndarray, sides_by_order, bark_target: int,
                           metres_per_px: float):
    """The (simplified skeleton, original_node, leaf_anchor) that draws the bark within `bark_target` triangles
    with the least estimated silhouette error at `metres_per_px`, or None when not even the trunk fits.

    For each tolerance of the ladder (up to _MAX_WEIGHED_TOLERANCE_PX), every branch keeps the nodes
    Douglas-Peucker needs to stay within it (THICK_TOLERANCE_PX for thick branches), and the branches are kept
    in order of the largest area drawn on screen in their subtree (length x width, at least one pixel wide),
    until the budget is spent. The error of a choice is the area of the dropped branches plus, per kept
    branch, its length x the largest offset its dropped nodes had (at most its width: a thin line moved off
    costs its own width); the tolerance with the least error wins (the finest on ties). keys: (N,) float64
    metres, `branch_node_keys(skeleton)`.
    """
    starts = skeleton.branch_starts
    sides, coned = _branch_sides(skeleton, sides_by_order, metres_per_px)
    width_px = np.maximum(2.0 * skeleton.radius[starts].astype(np.float64) / metres_per_px, 1.0)
    length_px = _branch_lengths(skeleton) / metres_per_px
    area = length_px * width_px
    parent = skeleton.branch_parent
    area[0] = np.inf  # the trunk always stays
    rank = np.lexsort((np.arange(len(starts)), skeleton.depth[starts], -subtree_maximum(area, parent)))
    area[0] = 0.0
    junction = skeleton.parent[starts]
    # A kept child needs its junction node in the parent: where a tolerance drops that node, it is charged to
    # the child (an upper bound when two children share one).
    junction_cost = np.where(junction >= 0, 2 * sides[np.maximum(parent, 0)], 0)
    junction = np.maximum(junction, 0)
    limit_px = np.where(width_px >= THICK_BRANCH_PX, THICK_TOLERANCE_PX, np.inf)
    best = None
    for tolerance_px in TOLERANCE_LADDER_PX:
        if tolerance_px > _MAX_WEIGHED_TOLERANCE_PX:
            break
        kept_node = keys > np.minimum(limit_px, tolerance_px)[skeleton.branch_id] * metres_per_px
        kept_node[starts] = True
        kept_node[0] = True
        costs = _branch_triangles(skeleton, kept_node, sides, coned) + np.where(kept_node[junction], 0, junction_cost)
        n_kept = int(np.searchsorted(np.cumsum(costs[rank]), bark_target, side="right"))
        if n_kept == 0:
            continue
        kept_branch = np.zeros(len(starts), bool)
        kept_branch[rank[:n_kept]] = True
        dropped_node_px = np.where(kept_node, 0.0, keys / metres_per_px)
        offset_px = np.zeros(len(starts))
        np.maximum.at(offset_px, skeleton.branch_id, dropped_node_px)
        error = area[~kept_branch].sum() + (length_px * np.minimum(offset_px, width_px))[kept_branch].sum()
        if best is None or error < best[0]:
            best = (error, kept_node, kept_branch)
    if best is None:
        return None
    _, kept_node, kept_branch = best
    return _skeleton_from_mask(skeleton, _with_structure(skeleton, kept_node, ~kept_branch))


def metres_per_pixel(skeleton: Skeleton, switch_px: int) -> float:
    """Metres a screen pixel spans when the tree's larger extent (height or width) is `switch_px` pixels."""
    lo, hi = np.asarray(skeleton.bounds, np.float64)
    return max(float(np.max(hi - lo)), 1e-6) / switch_px


class TreeLods:
    """Levels of detail of one tree: what every level and bark share needs (Douglas-Peucker keys of the nodes,
    the leaf cards prepared for clustering) is computed once, on first use."""

    def __init__(self, skeleton: Skeleton, lod0: TreeMesh):
        self.skeleton, self.lod0 = skeleton, lod0
        self.barks: dict[tuple, tuple] = {}  # (level, target, switch px, bark share[, "twigs"]) -> fitted bark
        self._twigs: dict[tuple, TwigCards] = {}  # (kept branches, depth, planes) -> cards
        self._kept_leaf_cards: dict[bytes, LeafCards] = {}  # kept branches -> their leaves, prepared to cluster

    @cached_property
    def node_keys(self) -> np.ndarray:
        return branch_node_keys(self.skeleton)

    @cached_property
    def leaf_cards(self) -> LeafCards:
        return LeafCards(self.skeleton.leaves)

    def twig_cards(self, kept_branch: np.ndarray, room: int, max_planes: int = TWIG_CARD_PLANES,
                   planes_first: bool = False, leaves: bool = True) -> TwigCards:
        """Twig cards for the branches not kept ((B,) bool) within `room` triangles: TWIG_CARD_PLANES crossed cards
        per cluster, clusters split as finely as TWIG_DEPTHS allows, and more planes, up to `max_planes`, where
        the room holds them; where not even one crossed pair per dropped subtree fits, one card per cluster;
        LodBudgetError when not even that fits. `planes_first`: as many planes as fit (`max_planes`, then half
        as many, ...), clusters as fine as those planes allow (a far level's few clusters are seen from between
        their planes, where more planes on coarser clusters beat fewer on finer ones; docs/library.md). Without
        `leaves`, bark cards (`twig_cards`)."""
        if planes_first:
            ladder = [max_planes >> k for k in range(max_planes.bit_length()) if max_planes >> k >= 1]
        else:
            ladder = list(dict.fromkeys((TWIG_CARD_PLANES, 1)))
        for planes in ladder:
            for depth in TWIG_DEPTHS:
                labels = twig_labels(self.skeleton, kept_branch, depth)
                clusters = int(labels.max(initial=-1)) + 1
                if _CARD_TRIANGLES * planes * clusters <= room:
                    if not planes_first and planes == TWIG_CARD_PLANES:
                        planes = max(planes, min(max_planes, room // max(_CARD_TRIANGLES * clusters, 1)))
                    key = (kept_branch.tobytes(), depth, planes, leaves)
                    if key not in self._twigs:
                        self._twigs[key] = twig_cards(self.skeleton, self.lod0, labels, planes, leaves)
                    return self._twigs[key]
        raise LodBudgetError(f"{room} triangles leave no room for one twig card per dropped subtree")

    def build(self, level: int, budget: float, switch_px: int | None = None, bark_share: float | None = None,
              card_area_gain: float = CLUSTER_AREA_GAIN, twigs: bool = False, twig_planes: int = TWIG_CARD_PLANES,
              planes_first: bool = False, twig_leaves: bool = True) -> LodLevel:
        """`build_lod` of this tree; with `twigs`, the branches the level drops are drawn as twig cards
        (`TreeLods.twig_cards`, with `twig_planes` as its max_planes and `planes_first`) instead of going to the
        leaf clusters. Without `twig_leaves` they are bark cards: their leaves stay with the leaf cards, which get
        one card per leaf where the budget holds them, else at least half of what the bark leaves."""
        skeleton, lod0 = self.skeleton, self.lod0
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
        if bark_share is None:
            bark_share = lod0.bark.n_faces / max(total0, 1)
        elif not 0.0 <= bark_share <= 1.0:
            raise LodBudgetError(f"bark share {bark_share!r} for LOD{level} is invalid: allowed a fraction in [0, 1]")
        if not card_area_gain > 0:
            raise LodBudgetError(f"card area gain {card_area_gain!r} for LOD{level} is invalid: allowed a number > 0")
        key = (level, target, int(switch_px), float(bark_share))
        if key not in self.barks:  # the bark does not depend on the cards' gain: fitted once per share
            self.barks[key] = _fit_bark(self, level, budget, target, int(switch_px), bark_share)
        if twigs and self.barks[key][4]:
            # The fallback bark took the whole budget: with twig cards, it keeps to its share instead (down to the
            # trunk alone), and the cards draw what it drops.
            key = key + ("twigs",)
            if key not in self.barks:
                self.barks[key] = _fit_bark(self, level, budget, target, int(switch_px), bark_share, keep_share=True)
        simplified, original, leaf_anchor, bark, _ = self.barks[key]
        leaf_budget = target - bark.n_faces
        leaf_cards, cards_made = self.leaf_cards, None
        if twigs:
            kept_branch = np.zeros(skeleton.n_branches, bool)
            kept_branch[skeleton.branch_id[original]] = True
            if kept_branch.all():
                raise LodBudgetError(f"LOD{level} keeps every branch: no twig cards to draw")
            if twig_leaves:
                leaf_kept = kept_branch[skeleton.branch_id[skeleton.leaf_node]]
                room = leaf_budget - (_CARD_TRIANGLES if leaf_kept.any() else 0)
            else:
                # Bark cards: the leaves stay cards of their own, as on a plain level; where they cannot all
                # be drawn one card each, the twig cards get at most half of what the bark leaves.
                room = leaf_budget - min(_CARD_TRIANGLES * len(leaf_cards), (leaf_budget + 1) // 2)
            cards_made = self.twig_cards(kept_branch, room, twig_planes, planes_first, twig_leaves)
            leaf_budget -= _CARD_TRIANGLES * len(cards_made)
            if twig_leaves:
                cache = kept_branch.tobytes()
                if cache not in self._kept_leaf_cards:
                    self._kept_leaf_cards[cache] = LeafCards(skeleton.leaves[leaf_kept])
                leaf_cards, leaf_anchor = self._kept_leaf_cards[cache], leaf_anchor[leaf_kept]
        n_clusters = leaf_budget // _CARD_TRIANGLES if len(leaf_cards) else 0
        if len(leaf_cards) and n_clusters < 1:
            raise LodBudgetError(f"LOD{level} budget {budget:.3f} leaves no room for a leaf card "
                                 f"({bark.n_faces} bark triangles of {target}); raise the LOD{level} budget")
        cards, card_node, merged = leaf_cards.cluster(leaf_anchor, int(n_clusters), card_area_gain)
        lod_skeleton = Skeleton(simplified.positions, simplified.parent, simplified.radius, simplified.order,
                                leaves=cards, leaf_node=card_node)
        leaves = leaf_part(lod_skeleton)
        leaves = MeshPart(leaves.vertices, leaves.faces, leaves.normals, leaves.uvs,
                          {**leaves.attributes, CLUMP_ATTRIBUTE: np.repeat(merged, 4).astype(np.uint8)})
        mesh = TreeMesh(bark=bark, leaves=leaves, bark_color=lod0.bark_color,
                        leaf_color=lod0.leaf_color, name=f"{lod0.name}_LOD{level}")
        return LodLevel(level, lod_skeleton, mesh, original.astype(np.int32), len(cards), cards_made)


def build_lod(skeleton: Skeleton, lod0: TreeMesh, level: int, budget: float, switch_px: int | None = None,
              bark_share: float | None = None, card_area_gain: float = CLUSTER_AREA_GAIN) -> LodLevel:
    """Level `level` (1..3) of detail within `budget` (fraction of LOD0 triangles), for viewing at `switch_px`
    pixels of tree size (default LOD_SWITCH_PX[level - 1]).

    The bark gets `bark_share` of the budget (default: its share of LOD0's triangles) and draws it with the
    least estimated silhouette error (see `_fit_bark_by_tolerance`): Douglas-Peucker nodes within a screen
    tolerance, branches kept by the area they draw. The leaves get the rest of the budget as cluster cards,
    each `card_area_gain` times the area its leaves cover (see `species.studio.leaf_clusters`). Raises LodBudgetError
    when nothing fits.
    """
    return TreeLods(skeleton, lod0).build(level, budget, switch_px, bark_share, card_area_gain)


def _fit_bark(lods: TreeLods, level: int, budget: float, target: int, switch_px: int, bark_share: float,
              keep_share: bool = False):
    """(simplified skeleton widened, original_node, leaf_anchor, bark MeshPart, fell_back) of a level whose bark
    may take `bark_share` of `target` triangles, leaving at least one card for the leaves; LodBudgetError if
    nothing fits. fell_back: True when no screen tolerance fitted and the fallback below was taken; there the bark
    may take all but one card. `keep_share` (for a share whose screen-tolerance search already failed) goes
    straight to the fallback and holds it to its share: twig cards draw the rest."""
    skeleton, total0 = lods.skeleton, lods.lod0.n_faces
    sides = LOD_SIDES[level - 1]
    min_leaf_tris = _CARD_TRIANGLES if skeleton.n_leaves else 0
    bark_target = max(int(target * bark_share), 0)
    if skeleton.n_leaves:
        bark_target = min(bark_target, target - min_leaf_tris)
    metres_per_px = metres_per_pixel(skeleton, switch_px)
    chosen = None if keep_share else _fit_bark_by_tolerance(skeleton, lods.node_keys, sides, bark_target,
                                                            metres_per_px)
    if chosen is None:
        # Fallback, as an artist would for a far tree: 3-sided tubes, the bark may take all but one card's
        # share, nodes thinned down to branch ends, first-order branches only, then the trunk's split clones
        # pruned like branches; the leaves go into the few cluster cards left.
        sides = (3,) * len(sides)
        if not keep_share:
            bark_target = target - min_leaf_tris
        chosen = _fit_bark_by_steps(skeleton, sides, bark_target, LOD_NODE_STEPS[level - 1],
                                    max(_MAX_NODE_STEP, int(skeleton.depth.max()) + 1), ((1, False), (1, True)))
        fell_back = True
    else:
        fell_back = False
    if chosen is None:
        raise LodBudgetError(f"LOD{level} budget {budget:.3f} x {total0} LOD0 triangles = {target} leaves no "
                             f"room for the trunk alone; raise the LOD{level} budget")
    simplified, original, leaf_anchor = chosen
    branch_sides, coned = _branch_sides(simplified, sides, metres_per_px)
    simplified = _widened(simplified, branch_sides)
    bark = bark_part(simplified, min_segments=3, branch_sides=branch_sides, tip_cones=coned)
    return simplified, original, leaf_anchor, bark, fell_back
