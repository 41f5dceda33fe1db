"""k-nearest-neighbour rows of some of a cloud's points read off one query of all of them, instead of a query each.

In: a cKDTree query of all the points with a column more than the rows wanted (`skeleton.cloud_neighbours`), the
subset kept (duplicates merged, outliers dropped) and, for the k-NN graph, the trunk's points moved. Out: the rows a
query of the subset itself gives. A row is read off only where nothing else can be among its k nearest, with no
distance tied at the edge (a query of other points may break such a tie otherwise); the other rows are queried
again, so the result is the subset's own query whatever the cloud.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["subset_neighbours", "moved_neighbours"]


def subset_neighbours(points: np.ndarray, kept: np.ndarray, distance: np.ndarray, index: np.ndarray,
                      k: int) -> tuple[np.ndarray, np.ndarray]:
    """(distances, indices), (M, k) each: cKDTree's k-nearest query of points[kept] among themselves (indices
    into them), read from a query of all `points` with more than k columns. A row whose first k + 1 distances all
    differ and whose first k neighbours are all kept holds the subset's k nearest, in their order (every other
    kept point is farther than the (k + 1)-th); the other rows are queried again."""
    subset = points[kept]
    k = min(k, len(subset))
    renumber = np.full(len(points), -1, np.int64)
    renumber[kept] = np.arange(len(kept))
    if distance.shape[1] <= k:
        return cKDTree(subset).query(subset, k=k)
    first = renumber[index[kept, :k]]
    near = distance[kept, :k].copy()
    again = np.flatnonzero(~(np.diff(distance[kept, :k + 1], axis=1) > 0).all(axis=1) | (first < 0).any(axis=1))
    if len(again):
        near[again], first[again] = cKDTree(subset).query(subset[again], k=k)
    return near, first


def moved_neighbours(points: np.ndarray, subset: np.ndarray, distance: np.ndarray, index: np.ndarray,
                     moved: np.ndarray, trunk: np.ndarray, k: int) -> np.ndarray | None:
    """(M, k) the k nearest of each of `moved` among them, as a set per row (the k-NN graph's edges), where
    `moved` is points[subset] with the `trunk` rows moved (`centralise_trunk`), read from a query of all `points`
    with more than k columns (None without one). A row is read off when its point and its k nearest are not trunk
    points, are all in the subset, are nearer than its (k + 1)-th, and every moved trunk point is farther: no other
    point can then be among its k nearest. The other rows are queried again."""
    if distance.shape[1] <= k or len(subset) <= k:
        return None
    renumber = np.full(len(points), -1, np.int64)
    renumber[subset] = np.arange(len(subset))
    nearest = renumber[index[subset, :k]]
    edge = distance[subset, k - 1]
    read = ~trunk & (nearest >= 0).all(axis=1) & (edge < distance[subset, k])
    read[read] = ~trunk[nearest[read]].any(axis=1)
    if trunk.any() and read.any():
        rows = np.flatnonzero(read)
        read[rows] = cKDTree(moved[trunk]).query(moved[rows], k=1)[0] > edge[rows]
    again = np.flatnonzero(~read)
    if len(again):
        nearest[again] = cKDTree(moved).query(moved[again], k=k)[1]
    return nearest
