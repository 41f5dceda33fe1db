"""Point cloud to skeleton, after AdTree's method (Du et al. 2019, "AdTree: Accurate, Detailed, and Automatic
Modelling of Laser-Scanned Trees"), in vectorised numpy and scipy.

In: a `PointCloud` (reconstruct.clouds: Z up, metres, base near the origin) or an (N, 3) array. Out: a `Skeleton`
(parent[i] < i, renumbered breadth-first, orders by `branch_orders`) with radii, and what was measured on the way.

The stages, each a function below:
1. duplicate removal (points closer than 1 mm become one), a voxel grid above `max_points`, and the
   statistical outlier filter (mean distance to 16 neighbours above the mean + 3 sigma);
2. the trunk's initial radius from the lowest 2 % of the points (a circle fit);
3. trunk centralisation: slice by slice up the trunk, the points on the fitted circle move to its centre, so the
   paths of step 5 climb the trunk's axis instead of spiralling round its bark;
4. the graph, edges weighted by squared length (a chain of short hops beats one long jump, so paths follow the
   wood and not the gaps between branches): by default the 16 nearest neighbours of each point, its pieces
   joined by their shortest links; AdTree's 3D Delaunay triangulation on request (`graph="delaunay"`), which
   fits a little closer and costs three times as long (benchmarks/bench_reconstruct_cloud.py);
5. the shortest-path tree from the lowest point (Dijkstra), and each point's path length along it;
6. merging of adjacent vertices: points in the same band of path length that touch become one skeleton vertex at
   their centroid (the band is a few point spacings wide, so a branch's cross-section is one vertex, and at most
   MAX_BAND_M, so a sparse scan's vertices stay near their points); then
   vertices closer than three bands at about the same path length join (the two flanks of a thick branch);
7. pruning of small subtrees: a side subtree whose reach (longest path to a tip) is below PRUNE_RATIO of the
   tree's reach goes;
8. merging of near-parallel siblings (their directions within 20 degrees): the weaker joins the stronger; and
   a side branch running beside its parent branch (90 % of it within 1.5 bands) is taken for the other flank
   of a thick limb and joins it (a thick limb sampled densely still keeps some such twigs);
9. removal of collinear single-child vertices (Douglas-Peucker along each branch at a share of the spacing);
10. the trunk cylinder fit (nonlinear least squares on the centralised trunk's original points), its radius on
    the trunk, and above it radii by the power law r = r_trunk (reach / reach at the trunk's top) ^ 1.1, never
    wider than the parent, and never thinner than one point spacing (at most MIN_RADIUS_CAP_M; 2 mm at least):
    the law thins twigs below what the scan resolves, and their points, a spacing or so apart, then lie beside
    the tube instead of on it;
11. Hermite smoothing: a cubic Hermite point inserted in every segment where the branch turns by more than 15
    degrees, so the tube bends smoothly without a dense skeleton.

AdTree's paper gives the power law's exponent (1.1) and a pruning ratio (0.019, ours is smaller: see PRUNE_RATIO);
the other constants are ours, chosen on the shared real scans (`tree1.xyz` and the others in
../shared/data/pointclouds/) and the synthetic clouds of `benchmarks/bench_reconstruct_cloud.py`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import Delaunay, QhullError, cKDTree

from species.geometry.topology import depth_levels, node_depths
from species.geometry.vectors import row_norms
from species.lsystem.lstring_io import branch_orders
from species.skeleton import Skeleton
from species.studio.lod import branch_node_keys, nearest_kept_ancestor, subtree_maximum
from species.timing import StageTimer

from .clouds import CloudError, PointCloud, read_cloud
from .knn_subsets import moved_neighbours, subset_neighbours
from .robust_fit import soft_l1_fit

__all__ = ["SkeletonSettings", "CloudSkeleton", "cloud_skeleton", "cloud_neighbours", "GRAPHS", "PRUNE_RATIO",
           "RADIUS_EXPONENT", "MAX_BAND_M"]

GRAPHS = ("delaunay", "knn")
# Side subtrees reaching less than this share of the tree's reach are removed. AdTree's paper prunes at 0.019;
# on sparse scans (airborne lidar) that removes measured twigs, each the only wood near its points.
PRUNE_RATIO = 0.005
# A path-length band is at most this wide, whatever the point spacing: a vertex stands for the points of its band,
# so on a sparse scan a band of a few spacings would put them beyond the fit's 10 cm bar.
MAX_BAND_M = 0.06
# Points are linked into one vertex at most this far apart, whatever the spacing: a vertex sits among its linked
# points, so on a sparse scan (airborne lidar) a link of a few spacings would leave them beyond the 10 cm bar.
MAX_LINK_M = 0.2
RADIUS_EXPONENT = 1.1      # AdTree: radius ~ (reach / trunk reach) ^ 1.1
# The thinnest radius follows the point spacing up to this: on a sparse scan (airborne lidar, a spacing of 15 cm)
# the spacing says nothing of a twig's width, and tubes that thick would stand off the points of thin branches.
MIN_RADIUS_CAP_M = 0.01
DUPLICATE_M = 1e-3         # points closer than this are one point
OUTLIER_NEIGHBOURS = 16    # the outlier filter's k nearest neighbours


@dataclass(frozen=True)
class SkeletonSettings:
    """The constants of `cloud_skeleton`; the defaults are the documented ones.

    max_points        : above this many (after duplicates go) the cloud is thinned on a voxel grid.
    outlier_sigma     : points whose mean distance to their 16 neighbours exceeds the mean by this many
                        standard deviations go (0 keeps all).
    graph             : "knn" (`knn` nearest neighbours, pieces joined) or "delaunay" (AdTree's, slower).
    band_spacings     : width of a path-length band in median point spacings (stage 6), at most max_band_m
                        metres.
    link_spacings     : points closer than this many spacings (at most max_link_m metres) and in one band are
                        one vertex.
    merge_bands       : stage 6b's distance, in bands.
    prune_ratio       : stage 7's share of the tree's reach.
    sibling_angle_deg : stage 8's angle.
    collinear_share   : stage 9's Douglas-Peucker tolerance, as a share of the band width.
    radius_exponent   : stage 10's power law.
    min_radius_m      : the thinnest branch radius written, in metres.
    min_radius_spacings : and in median point spacings, up to max_min_radius_m metres: a branch the scan resolves
                        spreads its points about a spacing wide, however thin the wood, so a thinner tube leaves
                        them beside it.
    hermite_angle_deg : stage 11's turning angle above which a segment gets a Hermite midpoint.
    """

    max_points: int = 50_000
    outlier_sigma: float = 3.0
    graph: str = "knn"
    knn: int = 16
    trunk_base_share: float = 0.02
    band_spacings: float = 4.0
    max_band_m: float = MAX_BAND_M
    link_spacings: float = 2.5
    max_link_m: float = MAX_LINK_M
    merge_bands: float = 0.0
    flank_bands: float = 1.5
    prune_ratio: float = PRUNE_RATIO
    sibling_angle_deg: float = 20.0
    collinear_share: float = 0.25
    radius_exponent: float = RADIUS_EXPONENT
    min_radius_m: float = 0.002
    min_radius_spacings: float = 1.0
    max_min_radius_m: float = MIN_RADIUS_CAP_M
    hermite_angle_deg: float = 15.0

    def __post_init__(self) -> None:
        if self.graph not in GRAPHS:
            raise CloudError(f"graph {self.graph!r} is not known: allowed {', '.join(GRAPHS)}")
        checks = {"max_points": (self.max_points, 1000), "knn": (self.knn, 3)}
        for name, (value, least) in checks.items():
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                raise CloudError(f"{name} = {value!r}: allowed an integer >= {least}")
        for name in ("outlier_sigma", "trunk_base_share", "band_spacings", "max_band_m", "link_spacings",
                     "max_link_m", "merge_bands", "flank_bands", "prune_ratio", "sibling_angle_deg",
                     "collinear_share", "radius_exponent", "min_radius_m", "min_radius_spacings", "max_min_radius_m",
                     "hermite_angle_deg"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
                raise CloudError(f"{name} = {value!r}: allowed a finite number >= 0")
        if not 0 < self.trunk_base_share < 0.5:
            raise CloudError(f"trunk_base_share = {self.trunk_base_share!r}: allowed a share in (0, 0.5)")


@dataclass(frozen=True, eq=False)
class CloudSkeleton:
    """What `cloud_skeleton` made and measured.

    skeleton      : the tree in the cloud's working frame (Z up, metres, the lowest point at Z = 0).
    trunk_radius  : metres, the fitted trunk cylinder's radius; trunk_axis : (2, 3) a point on the axis at the
                    base and the axis's unit direction.
    spacing       : metres, the median nearest-neighbour distance of the points used.
    n_points      : points given; n_used : points after duplicates and thinning; n_reached : points the
                    shortest-path tree reached (the others lie in pieces the graph could not join).
    timings       : seconds per stage.
    """

    skeleton: Skeleton
    trunk_radius: float
    trunk_axis: np.ndarray
    spacing: float
    n_points: int
    n_used: int
    n_reached: int
    timings: dict[str, float] = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------ stage 1
def unique_points(points: np.ndarray, max_points: int) -> np.ndarray:
    """(M, 3) float64: the points with duplicates (closer than DUPLICATE_M, on a 1 mm grid) merged, thinned on
    a voxel grid (one point per voxel, the first in file order) when more than `max_points` remain."""
    return points[unique_point_indices(points, max_points)]


def unique_point_indices(points: np.ndarray, max_points: int) -> np.ndarray:
    """(M,) ascending indices of the points `unique_points` keeps."""
    kept = _first_per_cell(points, DUPLICATE_M)
    if len(kept) <= max_points:
        return kept
    points = points[kept]
    extent = np.ptp(points, axis=0)
    # A scan samples surfaces, so the count falls with the voxel's area: start from the box's volume (a bound)
    # shrunk, then step by the square root of the excess until the cap is met (two or three passes).
    voxel = float(np.cbrt(np.prod(np.maximum(extent, 1e-3)) / max_points)) / 8
    while True:
        first = _first_per_cell(points, voxel)
        if len(first) <= max_points:
            return kept[first]
        voxel *= max(np.sqrt(len(first) / max_points), 1.05)


def _first_per_cell(points: np.ndarray, cell: float) -> np.ndarray:
    """Ascending indices of the first point in each occupied cell of a grid of side `cell` (one int64 key per
    cell: a 1-D unique is several times faster than a row-wise one)."""
    keys = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
    span = keys.max(axis=0) + 1
    flat = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
    _, first = np.unique(flat, return_index=True)
    return np.sort(first)


def statistical_inliers(points: np.ndarray, k: int = OUTLIER_NEIGHBOURS, sigma: float = 2.0, link: float = 2.0,
                        neighbours: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N,) bool: points whose mean distance to their k nearest neighbours is within the cloud's mean + `sigma`
    standard deviations of it (digest 3.1's outlier filter; stray returns in the air are far from everything),
    and the points above that bound that still hang together with more than k others (each linked to a neighbour
    within `link` x the bound): the sparse top of a crown is thinly sampled, not stray. `neighbours`: the points'
    own cKDTree query with k + 1 (itself first), where the caller has it already."""
    distance, index = cKDTree(points).query(points, k=min(k + 1, len(points))) if neighbours is None else neighbours
    mean = distance[:, 1:].mean(axis=1)
    bound = mean.mean() + sigma * mean.std()
    inlier = mean <= bound
    if inlier.all():
        return inlier
    linked = distance[:, 1:] <= link * bound
    rows = np.repeat(np.arange(len(points)), index.shape[1] - 1)[linked.ravel()]
    _, group = connected_components(_adjacency(np.column_stack([rows, index[:, 1:][linked]]), len(points)),
                                    directed=False)
    return inlier | (np.bincount(group)[group] > k)


def cloud_neighbours(cloud) -> tuple[np.ndarray, np.ndarray]:
    """(distances, indices), (N, k) each: the OUTLIER_NEIGHBOURS + 2 nearest points of each point of a PointCloud
    or an (N, 3) array (itself first, float64 distances), the query the outlier filter and `reconstruct.wood`'s
    scattering share: one column more than either reads, so that their own rows, and those of a subset of the
    points, are read off it where no distance ties at the edge (`subset_neighbours`)."""
    points = np.asarray(cloud.points if isinstance(cloud, PointCloud) else cloud, np.float64)
    return cKDTree(points).query(points, k=min(OUTLIER_NEIGHBOURS + 2, len(points)))


def nearest_kept(distance: np.ndarray, index: np.ndarray, kept: np.ndarray) -> np.ndarray | None:
    """(M,) each kept point's distance to the nearest other kept point, read from the k-NN query of all the
    points ((N, k) sorted rows, each point itself first): the first kept neighbour in its row is the nearest;
    None when a kept point has no kept neighbour in its row (the caller queries the kept points then)."""
    rows = kept[index[kept, 1:]]
    if not rows.any(axis=1).all():
        return None
    return distance[kept, 1:][np.arange(len(rows)), np.argmax(rows, axis=1)]


# ------------------------------------------------------------------------------------------------ stages 2, 3
def fit_circle(xy: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (2,) and radius of the least-squares circle through 2D points (the algebraic fit: linear, exact for
    points on a circle, and good on an arc, as a scan of one side of a trunk gives)."""
    a = np.column_stack([2.0 * xy, np.ones(len(xy))])
    b = np.einsum("ij,ij->i", xy, xy)
    (cx, cy, c), *_ = np.linalg.lstsq(a, b, rcond=None)
    return np.array([cx, cy]), float(np.sqrt(max(c + cx * cx + cy * cy, 0.0)))


def _planar_norms(xy: np.ndarray) -> np.ndarray:
    return np.hypot(xy[..., 0], xy[..., 1])


def centralise_trunk(points: np.ndarray, base_share: float, spacing: float,
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Stages 2 and 3. Returns (points with the trunk's moved onto its axis, trunk mask, (K, 3) axis centres of
    the slices, initial radius). Slices one band high climb while their points still fit one circle no wider
    than twice the base radius; the climb stops at the first fork or where the trunk disappears into the crown."""
    z = points[:, 2]
    low = z <= np.quantile(z, base_share)
    base = points[low]
    # The stem's foot is the largest group of touching low points; strays near the ground are not part of it.
    pairs = cKDTree(base).query_pairs(3.0 * spacing, output_type="ndarray")
    _, group = connected_components(_adjacency(pairs, len(base)), directed=False)
    base = base[group == np.argmax(np.bincount(group))]
    centre, radius0 = fit_circle(base[:, :2])
    spread = np.median(_planar_norms(base[:, :2] - np.median(base[:, :2], axis=0)))
    if not np.isfinite(radius0) or radius0 > 4 * max(spread, spacing):  # too few or collinear points: no arc
        centre, radius0 = np.median(base[:, :2], axis=0), float(spread)
    radius0 = max(radius0, spacing)
    height = max(2.0 * radius0, 4.0 * spacing)
    trunk = np.zeros(len(points), bool)
    centres, radius, bottom, top = [], radius0, float(z.min()), float(z.max())
    order = np.argsort(z, kind="stable")
    sorted_z = z[order]
    while bottom < top:
        lo, hi = np.searchsorted(sorted_z, [bottom, bottom + height])
        index = order[lo:hi]
        near = index[_planar_norms(points[index, :2] - centre) <= 2.0 * radius + 2 * spacing]
        if len(near) < 6:
            break
        new_centre, new_radius = fit_circle(points[near, :2])
        if not np.isfinite(new_radius) or new_radius > 2.0 * radius0 or _planar_norms(new_centre - centre) > 2 * radius:
            break
        centre, radius = new_centre, max(new_radius, spacing)
        on = near[_planar_norms(points[near, :2] - centre) <= 1.5 * radius + spacing]
        trunk[on] = True
        centres.append([centre[0], centre[1], bottom + height / 2])
        bottom += height
    moved = points.copy()
    if centres:
        axis = np.asarray(centres)
        slice_of = np.clip(np.searchsorted(axis[:, 2], points[trunk, 2]), 0, len(axis) - 1)
        # A tenth of the offset stays, so the centralised points do not fall into one degenerate line.
        moved[trunk, :2] = axis[slice_of, :2] + 0.1 * (points[trunk, :2] - axis[slice_of, :2])
    else:
        axis = np.array([[centre[0], centre[1], float(z.min())]])
    return moved, trunk, axis, radius0


# ------------------------------------------------------------------------------------------------ stage 4
def graph_edges(points: np.ndarray, graph: str, knn: int, nearest: np.ndarray | None = None) -> np.ndarray:
    """(E, 2) int64 unique undirected edges (i < j): the 3D Delaunay triangulation's, or the k-NN graph's with
    its pieces joined by their shortest links (Boruvka steps), so that every point can be reached either way.
    nearest : (N, knn + 1) each point's knn + 1 nearest (itself among them), where the caller has them
    (`knn_subsets.moved_neighbours`)."""
    n = len(points)
    if graph == "delaunay":
        try:
            simplices = Delaunay(points, qhull_options="QJ Qbb").simplices
        except QhullError as error:
            raise CloudError(f"the cloud's points are degenerate (all on a plane or a line?): {error}".splitlines()[0]
                             ) from None
        return _unique_edges(simplices[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]].reshape(-1, 2), n)
    tree = cKDTree(points)
    index = tree.query(points, k=min(knn + 1, n))[1] if nearest is None else nearest
    edges = _unique_edges(np.column_stack([np.repeat(np.arange(n), index.shape[1] - 1), index[:, 1:].ravel()]), n)
    count, label = connected_components(_adjacency(edges, n), directed=False)
    while count > 1:
        links = _bridges(points, tree, label, count)
        edges = _with_edges(edges, links, n)
        # The pieces the links join, found on the graph of pieces: the labels the whole graph's would have (each
        # piece's label follows its first point's index, and so does each joined piece's).
        count, joined = connected_components(_adjacency(label[links], count), directed=False)
        label = joined[label]
    return edges


_BRIDGE_NEIGHBOURS = 32  # neighbours searched for a link out of a piece of the k-NN graph


def _unique_edges(pairs: np.ndarray, n: int) -> np.ndarray:
    pairs = np.sort(pairs.astype(np.int64), axis=1)
    flat = np.sort(pairs[:, 0] * n + pairs[:, 1])   # a sort and a neighbour test: numpy's hashing unique is slower
    flat = flat[np.r_[True, flat[1:] != flat[:-1]] & (flat // n != flat % n)]
    return np.column_stack([flat // n, flat % n])


def _with_edges(edges: np.ndarray, pairs: np.ndarray, n: int) -> np.ndarray:
    """`_unique_edges` of `edges` (its own output) and a few more `pairs`: the new ones put in their places, not
    the whole graph sorted again."""
    added = _unique_edges(pairs, n)
    if not len(edges):
        return added
    flat = edges[:, 0] * n + edges[:, 1]
    added_flat = added[:, 0] * n + added[:, 1]
    at = np.searchsorted(flat, added_flat)
    new = (at == len(flat)) | (flat[np.minimum(at, len(flat) - 1)] != added_flat)
    return np.insert(edges, at[new], added[new], axis=0)


def _adjacency(edges: np.ndarray, n: int) -> sparse.coo_matrix:
    return sparse.coo_matrix((np.ones(len(edges), np.int8), (edges[:, 0], edges[:, 1])), shape=(n, n))


def _bridges(points: np.ndarray, tree: cKDTree, label: np.ndarray, count: int) -> np.ndarray:
    """(B, 2) the shortest link from each piece but the largest to another (a Boruvka step): among the nearest
    neighbours of a piece's points, the first in another piece; a piece that sees no other searches the rest."""
    largest = np.argmax(np.bincount(label, minlength=count))
    query = np.flatnonzero(label != largest)
    _, index = tree.query(points[query], k=min(_BRIDGE_NEIGHBOURS, len(points)))
    label_query = label[query]
    other = label[index] != label_query[:, None]
    has = other.any(axis=1)
    first = np.argmax(other, axis=1)
    source = query[has]
    target = index[has, first[has]]
    length = row_norms(points[source] - points[target])
    ranked = np.lexsort((length, label[source]))
    best = ranked[np.r_[True, label[source][ranked][1:] != label[source][ranked][:-1]]] if len(ranked) else ranked
    links = [np.column_stack([source[best], target[best]])]
    for piece in np.setdiff1d(np.arange(count), np.r_[largest, label[source[best]]]):  # far pieces: rare, one search each
        inside = np.flatnonzero(label == piece)
        outside = np.flatnonzero(label != piece)
        distance, nearest = cKDTree(points[outside]).query(points[inside])
        at = int(np.argmin(distance))
        links.append(np.array([[inside[at], outside[nearest[at]]]]))
    return np.concatenate(links)


# ------------------------------------------------------------------------------------------------ stage 5
def path_sums(step: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """(N,) the sum of `step` over each node and all its ancestors (parent -1 at roots), by pointer jumping:
    each pass doubles the hops summed, so log2(depth) vectorised passes."""
    total, ancestor = np.asarray(step, np.float64).copy(), np.asarray(parent, np.int64).copy()
    while True:
        has = np.flatnonzero(ancestor >= 0)
        if not len(has):
            return total
        total[has] += total[ancestor[has]]
        ancestor[has] = ancestor[ancestor[has]]


def shortest_path_tree(points: np.ndarray, edges: np.ndarray, root: int) -> tuple[np.ndarray, np.ndarray]:
    """(predecessor (N,) int64, -1 at the root and at unreached points; path length (N,) metres along the tree,
    inf where unreached). Edge weights are squared lengths."""
    n = len(points)
    length = row_norms(points[edges[:, 1]] - points[edges[:, 0]])
    weights = sparse.coo_matrix((np.maximum(length, 1e-9) ** 2, (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    _, predecessor = dijkstra(weights, directed=False, indices=root, return_predecessors=True)
    predecessor = np.where(predecessor < 0, -1, predecessor).astype(np.int64)
    reached = predecessor >= 0
    reached[root] = True
    step = np.zeros(n)
    step[predecessor >= 0] = row_norms(points[predecessor >= 0] - points[predecessor[predecessor >= 0]])
    return predecessor, np.where(reached, path_sums(step, predecessor), np.inf)


# ------------------------------------------------------------------------------------------------ stage 6
def merge_bands(points: np.ndarray, edges: np.ndarray, predecessor: np.ndarray, path_length: np.ndarray,
                band: float, link: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Vertices from touching points of one path-length band. Returns (positions (K, 3) centroids, parent (K,)
    int64 with -1 at the root, points (K,) per vertex, path length (K,) of each vertex's first point); vertices
    are sorted by that path length, so every parent comes before its children."""
    reached = np.isfinite(path_length)
    n = len(points)
    bands = np.where(reached, np.floor(np.where(reached, path_length, 0.0) / band), -1.0)
    a, b = edges[:, 0], edges[:, 1]
    length = row_norms(points[a] - points[b])
    joined = reached[a] & reached[b] & (bands[a] == bands[b]) & (length <= link)
    tree_edge = np.flatnonzero(predecessor >= 0)
    same = bands[tree_edge] == bands[predecessor[tree_edge]]
    rows = np.concatenate([a[joined], tree_edge[same]])
    cols = np.concatenate([b[joined], predecessor[tree_edge[same]]])
    graph = sparse.coo_matrix((np.ones(len(rows), np.int8), (rows, cols)), shape=(n, n))
    _, component = connected_components(graph, directed=False)
    used = np.flatnonzero(reached)
    first_order = used[np.lexsort((path_length[used], component[used]))]
    first = first_order[np.r_[True, component[first_order][1:] != component[first_order][:-1]]]
    # Number vertices by their first point's path length: a parent's first point is nearer the root.
    first = first[np.argsort(path_length[first], kind="stable")]
    vertex_of_component = np.full(component.max() + 1, -1, np.int64)
    vertex_of_component[component[first]] = np.arange(len(first))
    label = np.where(reached, vertex_of_component[component], -1)
    counts = np.bincount(label[used], minlength=len(first)).astype(np.float64)
    positions = np.column_stack([np.bincount(label[used], points[used, k], len(first)) for k in range(3)])
    positions /= counts[:, None]
    parent = np.where(predecessor[first] >= 0, label[np.maximum(predecessor[first], 0)], -1)
    return positions, parent, counts, path_length[first]


def merge_close_vertices(positions: np.ndarray, parent: np.ndarray, weight: np.ndarray, along: np.ndarray,
                         distance: float, band: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stage 6b: vertices closer than `distance` whose path lengths differ by less than two bands become one
    (their weighted centroid). A thick branch's bark is reached round both sides, and the bands cut its two
    flanks into parallel chains; this joins them. Returns (positions, parent, weight), parents first."""
    pairs = cKDTree(positions).query_pairs(distance, output_type="ndarray")
    pairs = pairs[np.abs(along[pairs[:, 0]] - along[pairs[:, 1]]) < 2 * band]
    n = len(positions)
    _, component = connected_components(_adjacency(pairs, n), directed=False)
    ranked = np.lexsort((along, component))
    first = ranked[np.r_[True, component[ranked][1:] != component[ranked][:-1]]]
    first = first[np.argsort(along[first], kind="stable")]
    vertex_of = np.full(component.max() + 1, -1, np.int64)
    vertex_of[component[first]] = np.arange(len(first))
    label = vertex_of[component]
    total = np.bincount(label, weight, len(first))
    merged = np.column_stack([np.bincount(label, weight * positions[:, k], len(first)) for k in range(3)])
    merged /= total[:, None]
    new_parent = np.where(parent[first] >= 0, label[np.maximum(parent[first], 0)], -1)
    return merged, new_parent, total


# ------------------------------------------------------------------------------------------------ stages 7-9
def _edge_lengths(positions: np.ndarray, parent: np.ndarray) -> np.ndarray:
    length = np.zeros(len(parent))
    has = parent >= 0
    length[has] = row_norms(positions[has] - positions[parent[has]])
    return length


def _reach(positions: np.ndarray, parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(path length from the root, reach: the longest path from each vertex down to a tip), metres."""
    along = path_sums(_edge_lengths(positions, parent), parent)
    return along, subtree_maximum(along, parent) - along


def _dominant_child(parent: np.ndarray, strength: np.ndarray) -> np.ndarray:
    """(N,) bool: the child of greatest strength among its siblings (the first on ties); False at the root."""
    child = np.flatnonzero(parent >= 0)
    ranked = child[np.lexsort((child, -strength[child], parent[child]))]
    dominant = np.zeros(len(parent), bool)
    dominant[ranked[np.r_[True, parent[ranked][1:] != parent[ranked][:-1]]]] = True
    return dominant


def _spread_down(flag: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """(N,) bool: flagged, or below a flagged vertex."""
    flag = flag.copy()
    for level in depth_levels(node_depths(parent)):
        flag[level] |= flag[parent[level]]
    return flag


def _keep(positions: np.ndarray, parent: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The kept vertices, each re-parented to its nearest kept ancestor (the root is kept)."""
    keep = keep.copy()
    keep[0] = True
    anchor = nearest_kept_ancestor(parent, keep)
    index = np.flatnonzero(keep)
    new = np.full(len(parent), -1, np.int64)
    new[index] = np.arange(len(index))
    new_parent = np.where(parent[index] >= 0, new[anchor[np.maximum(parent[index], 0)]], -1)
    return positions[index], new_parent


def breadth_first(positions: np.ndarray, parent: np.ndarray, *values: np.ndarray):
    """Renumber a tree breadth-first (by depth, then by path length): parent[i] < i afterwards."""
    depth = node_depths(parent)
    along = path_sums(_edge_lengths(positions, parent), parent)
    order = np.lexsort((along, depth))
    new = np.empty(len(order), np.int64)
    new[order] = np.arange(len(order))
    new_parent = np.where(parent[order] >= 0, new[np.maximum(parent[order], 0)], -1)
    return (positions[order], new_parent) + tuple(v[order] for v in values)


def prune_small_subtrees(positions: np.ndarray, parent: np.ndarray, ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Stage 7: a side subtree (not its parent's longest-reaching child) whose reach, its first edge included,
    is below `ratio` x the tree's reach is removed with everything on it."""
    _, reach = _reach(positions, parent)
    reach_in = reach + _edge_lengths(positions, parent)
    side = (parent >= 0) & ~_dominant_child(parent, reach_in)
    drop = _spread_down(side & (reach_in < ratio * reach[0]), parent)
    return _keep(positions, parent, ~drop)


def merge_parallel_siblings(positions: np.ndarray, parent: np.ndarray, angle_deg: float,
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Stage 8: a side child whose direction from the parent lies within `angle_deg` of the strongest sibling's
    is merged into it: its children hang from the strongest sibling and it goes."""
    _, reach = _reach(positions, parent)
    dominant = _dominant_child(parent, reach + _edge_lengths(positions, parent))
    child = np.flatnonzero(parent >= 0)
    direction = np.zeros_like(positions)
    offset = positions[child] - positions[parent[child]]
    direction[child] = offset / np.maximum(row_norms(offset), 1e-12)[:, None]
    strongest = np.full(len(parent), -1, np.int64)
    strongest[parent[dominant]] = np.flatnonzero(dominant)
    side = child[~dominant[child]]
    partner = strongest[parent[side]]
    merge = side[np.einsum("ij,ij->i", direction[side], direction[partner]) >= np.cos(np.radians(angle_deg))]
    if not len(merge):
        return positions, parent
    into = np.arange(len(parent))
    into[merge] = strongest[parent[merge]]
    new_parent = np.where(parent >= 0, into[np.maximum(parent, 0)], -1)
    keep = np.ones(len(parent), bool)
    keep[merge] = False
    index = np.flatnonzero(keep)
    new = np.full(len(parent), -1, np.int64)
    new[index] = np.arange(len(index))
    kept_parent = np.where(new_parent[index] >= 0, new[np.maximum(new_parent[index], 0)], -1)
    return breadth_first(positions[index], kept_parent)


def merge_flank_branches(positions: np.ndarray, parent: np.ndarray, distance: float, share: float = 0.9,
                         passes: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Stage 8b: a side branch that runs beside its parent branch (at least `share` of its vertices within
    `distance` of it) is the other flank of a thick limb, reached round the bark: it goes, and what grew on it
    hangs from the parent branch's nearest vertex. A branch under one that goes waits for the next pass, so a
    vertex is only ever re-hung on a branch that stays."""
    for _ in range(passes):
        skeleton = Skeleton(positions, parent, np.ones(len(parent), np.float32), np.zeros(len(parent), np.uint8))
        branch = skeleton.branch_id.astype(np.int64)
        starts = skeleton.branch_starts
        branch_parent = np.where(parent[starts] >= 0, branch[np.maximum(parent[starts], 0)], -1)
        k = min(16, len(positions))
        gap, near = cKDTree(positions).query(positions, k=k)
        target = branch_parent[branch]                                          # (N,) the parent branch
        on_parent = branch[near] == target[:, None]
        partner = np.where(on_parent.any(axis=1), near[np.arange(len(near)), np.argmax(on_parent, axis=1)], -1)
        beside = np.where(on_parent.any(axis=1), gap[np.arange(len(gap)), np.argmax(on_parent, axis=1)], np.inf)
        close = np.bincount(branch, beside <= distance, len(starts)) / np.bincount(branch, minlength=len(starts))
        flagged = (close >= share) & (branch_parent >= 0)
        above = _spread_down(flagged, branch_parent)
        has_flagged_ancestor = np.where(branch_parent >= 0, above[np.maximum(branch_parent, 0)], False)
        remove = flagged & ~has_flagged_ancestor
        if not remove.any():
            return positions, parent
        gone = remove[branch]
        hung = (parent >= 0) & ~gone & gone[np.maximum(parent, 0)]
        new_parent = parent.copy()
        new_parent[hung] = partner[parent[hung]]
        new_parent[hung & (new_parent < 0)] = parent[parent[hung & (new_parent < 0)]]  # no partner: its junction
        keep = ~gone
        index = np.flatnonzero(keep)
        renumber = np.full(len(parent), -1, np.int64)
        renumber[index] = np.arange(len(index))
        positions, parent = breadth_first(positions[index], np.where(new_parent[index] >= 0,
                                                                     renumber[np.maximum(new_parent[index], 0)], -1))
    return positions, parent


def drop_collinear(positions: np.ndarray, parent: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """Stage 9: single-child vertices whose Douglas-Peucker key along their branch is within `tolerance` metres
    (they lie that close to the chord the simplified branch keeps) go; tips and junctions stay."""
    skeleton = Skeleton(positions, parent, np.ones(len(parent), np.float32), np.zeros(len(parent), np.uint8))
    keep = (branch_node_keys(skeleton) > tolerance) | (skeleton.n_children != 1)
    return _keep(positions, parent, keep)


# ------------------------------------------------------------------------------------------------ stage 10
def fit_trunk_cylinder(points: np.ndarray, axis_centres: np.ndarray, radius0: float) -> tuple[float, np.ndarray]:
    """Radius and (2, 3) axis (a point at the base, unit direction) of the cylinder fitted by nonlinear least
    squares (soft-L1 loss, so branch stubs on the bark do not pull it) to the trunk's points. The start is the
    slice centres' line and the base circle's radius."""
    base = axis_centres[0]
    if len(axis_centres) >= 2:
        slope, *_ = np.linalg.lstsq(np.column_stack([axis_centres[:, 2] - base[2], np.ones(len(axis_centres))]),
                                    axis_centres[:, :2], rcond=None)
        tilt, start = slope[0], slope[1]
    else:
        tilt, start = np.zeros(2), base[:2]
    if len(points) < 8:
        direction = np.array([tilt[0], tilt[1], 1.0])
        return radius0, np.array([[start[0], start[1], base[2]], direction / row_norms(direction[None])[0]])
    z0 = base[2]

    def residual(x):
        d = np.array([x[2], x[3], 1.0])
        d /= np.sqrt(d @ d)
        rel = points - np.array([x[0], x[1], z0])
        return row_norms(rel - np.outer(rel @ d, d)) - x[4]

    # Bounded: the axis within about 17 degrees of the slice centres' line, the radius within a factor of 2.
    first = np.array([start[0], start[1], tilt[0], tilt[1], radius0])
    span = np.array([2 * radius0, 2 * radius0, 0.3, 0.3, 0.0])
    lower, upper = first - span, first + span
    lower[4], upper[4] = 0.5 * radius0, 2.0 * radius0
    x = soft_l1_fit(residual, first, lower, upper, max(0.2 * radius0, 1e-3))
    direction = np.array([x[2], x[3], 1.0])
    radius = float(x[4])
    return radius, np.array([[x[0], x[1], z0], direction / row_norms(direction[None])[0]])


def power_law_radii(positions: np.ndarray, parent: np.ndarray, trunk_radius: float, trunk_top: float,
                    exponent: float, min_radius: float) -> np.ndarray:
    """Stage 10's radii: the fitted trunk radius on the trunk (the longest-reaching path from the root, up to its
    first vertex above the top of the centralised trunk, `trunk_top` metres), and above and beside it trunk radius
    x (reach / reach at the trunk's top) ^ exponent, at least `min_radius`, never wider than the parent. Where the
    trunk ends at a tip (the longest path never climbs above `trunk_top`: the centralised trunk spans the scan, as on
    a stem clipped round like conifer_stems), the law has no reference and every vertex but the tips keeps the trunk radius."""
    along, reach = _reach(positions, parent)
    main = ~_spread_down((parent >= 0) & ~_dominant_child(parent, reach + _edge_lengths(positions, parent)), parent)
    # The path's first climb above trunk_top ends the trunk: a longest path that wanders back down through a
    # crown (a crown-only airborne scan) would otherwise make its far end, a tip of zero reach, the reference.
    above = main & (positions[:, 2] > trunk_top)
    if not above.any():
        return np.where(reach > 0, max(trunk_radius, min_radius), min_radius)
    trunk = main & (along < along[above].min())
    reference = reach[trunk].min() if trunk.any() else reach[0]
    radius = np.maximum(trunk_radius * (reach / max(reference, 1e-9)) ** exponent, min_radius)
    radius[trunk] = trunk_radius
    for level in depth_levels(node_depths(parent)):
        radius[level] = np.minimum(radius[level], radius[parent[level]])
    return radius


# ------------------------------------------------------------------------------------------------ stage 11
def hermite_midpoints(positions: np.ndarray, parent: np.ndarray, radius: np.ndarray, angle_deg: float):
    """Stage 11: a cubic Hermite (Catmull-Rom) midpoint in every segment whose branch turns by more than
    `angle_deg` at either end. Returns (positions, parent, radius), renumbered breadth-first."""
    skeleton = Skeleton(positions, parent, np.maximum(radius, 1e-6), np.zeros(len(parent), np.uint8))
    node = np.flatnonzero(parent >= 0)
    start = parent[node]
    before = np.where(parent[start] >= 0, parent[np.maximum(start, 0)], start)
    after = np.where(skeleton.continuation[node] >= 0, skeleton.continuation[node], node)
    p0, p1 = positions[start], positions[node]
    m0 = np.where((before == start)[:, None], p1 - p0, (p1 - positions[before]) / 2)
    m1 = np.where((after == node)[:, None], p1 - p0, (positions[after] - p0) / 2)
    chord = p1 - p0
    cos = np.cos(np.radians(angle_deg))

    def unit(v):
        return v / np.maximum(row_norms(v), 1e-12)[:, None]

    bent = (np.einsum("ij,ij->i", unit(m0), unit(chord)) < cos) | (np.einsum("ij,ij->i", unit(m1), unit(chord)) < cos)
    if not bent.any():
        return positions, parent, radius
    mid = 0.5 * (p0 + p1) + 0.125 * (m0 - m1)
    chosen = node[bent]
    new_ids = len(parent) + np.arange(len(chosen))
    positions = np.concatenate([positions, mid[bent]])
    new_parent = np.concatenate([parent, parent[chosen]])
    new_parent[chosen] = new_ids
    radius = np.concatenate([radius, 0.5 * (radius[chosen] + radius[parent[chosen]])])
    return breadth_first(positions, new_parent, radius)


# ------------------------------------------------------------------------------------------------ all stages
def cloud_skeleton(cloud, settings: SkeletonSettings | None = None, *, up: str = "z",
                   neighbours: tuple[np.ndarray, np.ndarray] | None = None) -> CloudSkeleton:
    """The skeleton of a tree's point cloud (stages 1-11 of the module's docstring).

    cloud    : a PointCloud, a path `read_cloud` opens, or an (N, 3) array (read with `up`).
    settings : the constants (SkeletonSettings()).
    neighbours : `cloud_neighbours(cloud)` where the caller has it already (the outlier filter's own query is read
               off it, `knn_subsets.subset_neighbours`).
    Raises CloudError for a cloud that cannot be a tree (too few points, degenerate, unreadable).
    """
    settings = SkeletonSettings() if settings is None else settings
    if not isinstance(settings, SkeletonSettings):
        raise CloudError(f"settings is a {type(settings).__name__}: allowed a SkeletonSettings")
    timer = StageTimer()
    lap, timings = timer.lap, timer.seconds

    if not isinstance(cloud, PointCloud):
        cloud = read_cloud(cloud, up=up)
    every = cloud.points.astype(np.float64)
    chosen = unique_point_indices(every, settings.max_points)
    points = every[chosen]
    # One k-NN query serves the outlier filter and the points' spacing (see `nearest_kept`), read off the caller's
    # query of the whole cloud where it has one.
    if neighbours is None:
        every, chosen = points, np.arange(len(points))
        neighbours = cloud_neighbours(points)
    whole = neighbours
    neighbours = subset_neighbours(every, chosen, *neighbours, OUTLIER_NEIGHBOURS + 1)
    kept = np.ones(len(points), bool)
    if settings.outlier_sigma > 0 and len(points) > 20:
        kept = statistical_inliers(points, OUTLIER_NEIGHBOURS, settings.outlier_sigma, neighbours=neighbours)
    points = points[kept]
    if len(points) < 20:
        raise CloudError(f"{cloud.source} has {len(points)} distinct points: allowed at least 20")
    gaps = nearest_kept(*neighbours, kept)
    spacing = float(np.median(cKDTree(points).query(points, k=2)[0][:, 1] if gaps is None else gaps))
    lap("duplicates")
    moved, trunk, axis_centres, radius0 = centralise_trunk(points, settings.trunk_base_share, spacing)
    lap("trunk")
    nearest = moved_neighbours(every, chosen[kept], *whole, moved, trunk, min(settings.knn + 1, len(moved))) \
        if settings.graph == "knn" else None
    edges = graph_edges(moved, settings.graph, settings.knn, nearest)
    lap("graph")
    root = int(np.argmin(np.where(trunk, moved[:, 2], np.inf))) if trunk.any() else int(np.argmin(moved[:, 2]))
    predecessor, along = shortest_path_tree(moved, edges, root)
    lap("shortest_paths")
    band = min(settings.band_spacings * spacing, settings.max_band_m)
    positions, parent, weight, first_along = merge_bands(moved, edges, predecessor, along, band,
                                                         min(settings.link_spacings * spacing, settings.max_link_m))
    if settings.merge_bands > 0:
        positions, parent, _ = merge_close_vertices(positions, parent, weight, first_along,
                                                    settings.merge_bands * band, band)
    lap("merge_vertices")
    positions, parent = prune_small_subtrees(positions, parent, settings.prune_ratio)
    positions, parent = merge_parallel_siblings(positions, parent, settings.sibling_angle_deg)
    positions, parent = merge_flank_branches(positions, parent, settings.flank_bands * band)
    positions, parent = prune_small_subtrees(positions, parent, settings.prune_ratio)
    positions, parent = drop_collinear(positions, parent, settings.collinear_share * band)
    lap("simplify")
    trunk_radius, trunk_axis = fit_trunk_cylinder(points[trunk], axis_centres, radius0)
    # Slice centres sit half a slice above their bottoms, and the first bottom is the lowest point, Z = 0.
    trunk_top = float(axis_centres[-1, 2] + axis_centres[0, 2]) if len(axis_centres) > 1 else 0.0
    radius = power_law_radii(positions, parent, trunk_radius, trunk_top, settings.radius_exponent,
                             max(settings.min_radius_m, min(settings.min_radius_spacings * spacing,
                                                            settings.max_min_radius_m)))
    lap("radii")
    positions, parent, radius = hermite_midpoints(positions, parent, radius, settings.hermite_angle_deg)
    # The tree stands on the ground, the cloud's lowest point (Z = 0), where the trunk's first slice begins: the
    # root goes down to it, and no vertex (a Hermite midpoint can overshoot a low bend) lies below it.
    positions[0, 2] = 0.0
    positions[:, 2] = np.maximum(positions[:, 2], 0.0)
    skeleton = Skeleton(positions.astype(np.float32), parent, radius.astype(np.float32),
                        branch_orders(positions, parent))
    lap("smooth")
    return CloudSkeleton(skeleton, trunk_radius, trunk_axis, spacing, len(cloud.points), len(points),
                         int(np.isfinite(along).sum()), timings)
