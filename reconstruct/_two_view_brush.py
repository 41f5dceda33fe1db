"""2D skeletons of brush strokes for the two-view method (seed 001, digest 2.2): stroke centres from row and column
runs, simplification, scored chain starts, circle-sweep linking of the chains, radius from the stroke width.

In: a (H, W) bool mask of brush strokes (pieces may be apart). Out: one `Skeleton2D` with a radius per point.
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ._sketch_arrays import mask_runs
from ._two_view_lines import Skeleton2D, check_mask

__all__ = ["skeleton_2d_from_brush", "stroke_centres"]

# Greedy chaining joins a point to the nearest unvisited centre within this distance (pixels): the 5x5 window.
_CHAIN_REACH = 2.9
# The linking circle's radius is this multiple of the skeleton radius (digest 2.2), and never below _MIN_SWEEP px.
_SWEEP_FACTOR = 2.0
_MIN_SWEEP = 2.0
# A tip path shorter than this multiple of the stroke radius at its fork is a spur of the centres, not a branch.
_SPUR_FACTOR = 4.0
_FORK_WINDOW = 4.0  # pixels around a fork where its stroke's half width is read
_EIGHT = np.array([(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)])
_SIXTEEN = np.array([(dy, dx) for dy in range(-2, 3) for dx in range(-2, 3) if max(abs(dy), abs(dx)) == 2])


def _width(across: np.ndarray, along: np.ndarray) -> np.ndarray:
    """Stroke width from a centre's run `across` and the perpendicular extent `along` through it: a straight
    stroke at angle a cuts runs w / cos a and w / sin a, so w = d1 d2 / hypot(d1, d2)."""
    return across * along / np.hypot(across, along)


def stroke_centres(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stroke centres by the row and column tests (digest 2.2).

    A horizontal run's midpoint is kept where the run is shorter than the vertical extent through it; a vertical
    run's midpoint where it is no longer than the horizontal extent through it. Returns the centre pixel map
    (H, W) bool (midpoints rounded down to a pixel) and the (H, W) float64 radius map, pixels: half the stroke
    width, corrected for slope (see `_width`), the largest where two centres share a pixel.
    """
    h, w = mask.shape
    rows, first, length, horizontal = mask_runs(mask)
    cols, top, height, vertical_t = mask_runs(mask.T)
    vertical = vertical_t.T
    centres = np.zeros((h, w), bool)
    radius = np.zeros((h, w))
    row_mid = first + (length - 1) // 2
    along = vertical[rows, row_mid]
    keep = length < along
    centres[rows[keep], row_mid[keep]] = True
    np.maximum.at(radius, (rows[keep], row_mid[keep]), _width(length[keep], along[keep]) / 2.0)
    col_mid = top + (height - 1) // 2
    across = horizontal[col_mid, cols]
    keep = height <= across
    centres[col_mid[keep], cols[keep]] = True
    np.maximum.at(radius, (col_mid[keep], cols[keep]), _width(height[keep], across[keep]) / 2.0)
    return centres, radius


def _simplify(centres: np.ndarray) -> np.ndarray:
    """The centre map thinned where it clumps (digest 2.2 simplification), in place order row by row: at a centre
    with more than two centre 8-neighbours, keep for each centre 16-neighbour one 8-neighbour next to it, plus the
    8-neighbours of extreme x or y; delete the other 8-neighbours."""
    c = np.pad(centres, 2)
    neighbours = cv2.filter2D(c.astype(np.uint8), -1, np.ones((3, 3), np.float32), borderType=cv2.BORDER_CONSTANT)
    # Deleting only lowers counts, so pixels with at most two neighbours now never need a look.
    for y, x in zip(*np.nonzero(c & (neighbours > 3))):
        if not c[y, x]:
            continue
        near = [(dy, dx) for dy, dx in _EIGHT if c[y + dy, x + dx]]
        if len(near) <= 2:
            continue
        near_arr = np.array(near)
        chosen = np.zeros(len(near), bool)
        for dy, dx in _SIXTEEN:
            if c[y + dy, x + dx]:
                touching = np.flatnonzero(np.abs(near_arr - (dy, dx)).max(axis=1) <= 1)
                if len(touching):
                    chosen[touching[0]] = True
        ny, nx = near_arr[:, 0], near_arr[:, 1]
        extreme = (ny == ny.min()) | (ny == ny.max()) | (nx == nx.min()) | (nx == nx.max())
        for (dy, dx) in near_arr[~(chosen | extreme)]:
            c[y + dy, x + dx] = False
    return c[2:-2, 2:-2]


def _chains(points: np.ndarray) -> list[np.ndarray]:
    """Chains of centre indices (each a path: at most two links per point), by greedy nearest unvisited neighbour
    from the best-scored start of what is left (digest 2.2: +3 extreme x, +3 extreme y in the point's group,
    +2 for exactly one 8-neighbour; ties to the lowest, then leftmost point)."""
    tree = cKDTree(points)
    reach = tree.query_ball_point(points, _CHAIN_REACH)
    eight = tree.query_ball_point(points, 1.5, return_length=True) - 1
    groups = _groups(tree, len(points))
    score = 2 * (eight == 1).astype(np.int64)
    for coord in (0, 1):
        value = points[:, coord]
        lo = np.full(groups.max() + 1, np.inf)
        hi = np.full(groups.max() + 1, -np.inf)
        np.minimum.at(lo, groups, value)
        np.maximum.at(hi, groups, value)
        score += 3 * ((value == lo[groups]) | (value == hi[groups]))
    # Start preference: best score, then lowest (largest y), then leftmost.
    preference = np.lexsort((points[:, 0], -points[:, 1], -score))
    visited = np.zeros(len(points), bool)
    chains = []
    for start in preference:
        if visited[start]:
            continue
        chain = [int(start)]
        visited[start] = True
        current = int(start)
        while True:
            options = [j for j in reach[current] if not visited[j]]
            if not options:
                break
            d = np.hypot(*(points[options] - points[current]).T)
            current = int(options[int(np.argmin(d))])
            visited[current] = True
            chain.append(current)
        chains.append(np.array(chain))
    return chains


def _groups(tree: cKDTree, n: int) -> np.ndarray:
    """(n,) int64, the 8-connected group of each centre point."""
    pairs = tree.query_pairs(1.5, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    return connected_components(graph, directed=False)[1]


def _link(points: np.ndarray, radius: np.ndarray, chains: list[np.ndarray]):
    """Join the chains into one tree by circle sweeps (digest 2.2): from the chain with the lowest endpoint, each
    linked chain sweeps a circle of _SWEEP_FACTOR x its radius along itself; an unlinked chain with an endpoint
    inside is linked there, turned to start at that endpoint. Chains no sweep reaches are linked at the endpoint
    nearest to the tree, nearest first. Returns chains (oriented) and the point each hangs from, in link order."""
    ends = np.array([[c[0], c[-1]] for c in chains])          # (C, 2) point indices
    end_tree = cKDTree(points[ends.ravel()])
    lowest = int(np.argmax(points[ends.ravel(), 1]))
    root_chain, root_end = divmod(lowest, 2)
    linked = np.zeros(len(chains), bool)
    oriented: list[np.ndarray] = []
    hang: list[int] = []

    def take(c: int, end: int, at: int) -> None:
        linked[c] = True
        oriented.append(chains[c] if end == 0 else chains[c][::-1])
        hang.append(at)

    take(root_chain, root_end, -1)
    swept = 0
    while True:
        while swept < len(oriented):
            chain = oriented[swept]
            swept += 1
            reach = np.maximum(_SWEEP_FACTOR * radius[chain], _MIN_SWEEP)
            hits = end_tree.query_ball_point(points[chain], reach)
            for k, found in enumerate(hits):
                for e in sorted(found):
                    c, end = divmod(e, 2)
                    if not linked[c]:
                        take(c, end, int(chain[k]))
        if linked.all():
            return oriented, hang
        tree_points = np.concatenate(oriented)
        distance, nearest = cKDTree(points[tree_points]).query(points[ends[~linked].ravel()])
        best = int(np.argmin(distance))
        c, end = divmod(best, 2)
        take(int(np.flatnonzero(~linked)[c]), end, int(tree_points[nearest[best]]))


def skeleton_2d_from_brush(mask, name: str = "sketch") -> Skeleton2D:
    """The 2D skeleton of a drawing in brush strokes, whose pieces may be apart (digest 2.2).

    mask : (H, W) bool (or 0/1), True on stroke pixels. name : the view's name in error messages.
    Centres come from the row and column run tests (`stroke_centres`), are thinned where they clump, chained
    from scored starts, and the chains are joined into one tree by circle sweeps starting from the chain with the
    lowest endpoint (the trunk base, largest row). Tip paths shorter than the stroke is wide at their fork are
    spurs (round stroke ends, fork wedges) and dropped.
    Returns a Skeleton2D whose points are centre pixels and whose radius is half the local stroke width (pixels);
    branch 0 starts at the lowest endpoint.
    """
    mask = check_mask(mask, name)
    centres, radius_map = stroke_centres(mask)
    centres = _simplify(centres)
    ys, xs = np.nonzero(centres)
    points = np.stack([xs, ys], axis=1).astype(np.float64)
    radius = np.maximum(radius_map[ys, xs], 0.5)
    if len(points) == 1:
        return Skeleton2D(points, [-1], radius, [0])
    chains, hang = _link(points, radius, _chains(points))
    order = np.concatenate(chains)
    new_index = np.full(len(points), -1, np.int64)
    new_index[order] = np.arange(len(order))
    sizes = np.array([len(c) for c in chains])
    branch = np.repeat(np.arange(len(chains)), sizes)
    parent = np.arange(len(order)) - 1
    firsts = np.cumsum(sizes) - sizes
    parent[firsts] = [new_index[h] if h >= 0 else -1 for h in hang]
    return _prune_spurs(Skeleton2D(points[order], parent, radius[order], branch), mask)


def _prune_spurs(skeleton: Skeleton2D, mask: np.ndarray) -> Skeleton2D:
    """The skeleton without spurs: tip paths (from a tip up to its nearest fork) shorter than _SPUR_FACTOR x the
    stroke's half width at the fork (the largest distance to the paper of the skeleton points within _FORK_WINDOW
    px of it, robust where run widths are not: at stroke ends and in fork wedges, whose centres leave such
    spurs)."""
    points, parent = skeleton.points, skeleton.parent
    paper_distance = cv2.distanceTransform(np.pad(mask, 1).astype(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1]
    pixel = points.astype(np.int64)
    radius = paper_distance[pixel[:, 1], pixel[:, 0]]
    children = skeleton.n_children.copy()
    keep = np.ones(len(skeleton), bool)
    spurs = []  # (length, fork, path) of every tip path that ends at a fork
    for tip in np.flatnonzero(children == 0):
        path, length, node = [], 0.0, int(tip)
        while node > 0 and children[node] <= 1:
            path.append(node)
            length += float(np.hypot(*(points[node] - points[parent[node]])))
            node = int(parent[node])
        if children[node] > 1:
            spurs.append((length, node, path))
    # A fork at a stroke's end (the trunk's base, where a round end's centres splay) lies a pixel from the paper:
    # its stroke's half width is the widest within _FORK_WINDOW px of it.
    forks = np.array([fork for _, fork, _ in spurs], np.int64)
    near = cKDTree(points).query_ball_point(points[forks], _FORK_WINDOW) if len(forks) else []
    width = {int(fork): float(radius[around].max()) for fork, around in zip(forks, near)}
    # Shortest first, so of two short paths at one fork the longer one stays as the branch.
    for length, fork, path in sorted(spurs, key=lambda s: s[0]):
        if length < _SPUR_FACTOR * width[fork] and children[fork] > 1:
            keep[path] = False
            children[fork] -= 1
    if keep.all():
        return skeleton
    new_index = np.cumsum(keep) - 1
    kept_parent = np.where(parent[keep] >= 0, new_index[np.maximum(parent[keep], 0)], -1)
    _, branch = np.unique(skeleton.branch[keep], return_inverse=True)
    return Skeleton2D(points[keep], kept_parent, skeleton.radius[keep], branch)
