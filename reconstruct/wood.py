"""Wood and leaves apart, by one geometric feature: the scattering of each point's neighbourhood.

For the k nearest neighbours of a point, the covariance's eigenvalues l1 >= l2 >= l3 say what the neighbourhood
looks like: a thin branch is a line (l2, l3 small), a trunk or limb a gently curved sheet (l3 small), a clump of
leaves a volume (l3 comparable with l1). The scattering l3 / l1 is the feature (Demantke et al.'s dimensionality
features); points above SCATTER_LEAF are taken for leaves. A cloud looks leaf-on when more than LEAF_ON_SHARE of its
crown (the points above CROWN_SHARE of its height) are leaves by this test. The thresholds were set between a
leaf-off scan, whose crown scatters only from scanner noise, and the same scan with leaf-like clutter
(docs/performance.md gives the shares).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["scattering", "wood_points", "leaf_on_share", "SCATTER_LEAF", "LEAF_ON_SHARE", "NEIGHBOURS"]

NEIGHBOURS = 16
SCATTER_LEAF = 0.2
LEAF_ON_SHARE = 0.4
CROWN_SHARE = 0.3


def scattering(points: np.ndarray, k: int = NEIGHBOURS, of: np.ndarray | None = None,
               neighbours: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(N,) l3 / l1 of each point's k-neighbourhood covariance, in [0, 1] (batched 3x3 eigenvalues); with `of`
    ((N,) bool), (M,) of those points only, their neighbours still found among all. `neighbours`: the points' own
    cKDTree query with more than k neighbours (`reconstruct.skeleton.cloud_neighbours`), where the caller has it."""
    points = np.asarray(points, np.float64)
    k = min(k, len(points))
    queried = points if of is None else points[of]
    if neighbours is None or neighbours[1].shape[1] <= k:
        index = cKDTree(points).query(queried, k=k)[1]
    else:
        index = _first_neighbours(points, queried, *(part if of is None else part[of] for part in neighbours), k)
    neighbourhood = points[index]
    local = neighbourhood - neighbourhood.mean(axis=1, keepdims=True)
    covariance = np.einsum("nki,nkj->nij", local, local) / k
    eigen = np.linalg.eigvalsh(covariance)                 # ascending
    return eigen[:, 0] / np.maximum(eigen[:, 2], 1e-18)


def _first_neighbours(points: np.ndarray, queried: np.ndarray, distance: np.ndarray, index: np.ndarray,
                      k: int) -> np.ndarray:
    """The k nearest of `points` to each of `queried`, in cKDTree's order, read from a query of more: the first k
    of a row are the k nearest, in the same order, where its distances all differ; a row with equal distances
    (which the two queries may order apart) is queried again for its own k."""
    tied = ~(np.diff(distance[:, :k + 1], axis=1) > 0).all(axis=1)
    first = index[:, :k].copy()
    if tied.any():
        first[tied] = cKDTree(points).query(queried[tied], k=k)[1]
    return first


def wood_points(points: np.ndarray, threshold: float = SCATTER_LEAF) -> np.ndarray:
    """(N,) bool, True for points whose neighbourhood is a line or a sheet (wood); the lowest CROWN_SHARE of the
    height (the stem) is always wood."""
    points = np.asarray(points)
    low = points[:, 2] <= points[:, 2].min() + CROWN_SHARE * np.ptp(points[:, 2])
    return low | (scattering(points) <= threshold)


def leaf_on_share(points: np.ndarray, threshold: float = SCATTER_LEAF,
                  neighbours: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """The share of crown points (above CROWN_SHARE of the height) that `wood_points` takes for leaves
    (`neighbours`: see `scattering`)."""
    points = np.asarray(points)
    crown = points[:, 2] > points[:, 2].min() + CROWN_SHARE * np.ptp(points[:, 2])
    if crown.sum() < NEIGHBOURS:
        return 0.0
    return float((scattering(points, of=crown, neighbours=neighbours) > threshold).mean())
