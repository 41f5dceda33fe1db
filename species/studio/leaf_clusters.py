"""Leaf cards merged into larger cluster cards on a voxel grid, for coarser levels of detail.

In: leaf transforms (M, 4, 4) of the unit card, the node each leaf hangs from, a cluster count. Out: cluster card
transforms (C, 4, 4), their nodes and which of them merge several leaves (a card that stands for one leaf is that
leaf, and is textured as one). `LeafCards` keeps what every cluster count of one tree shares.
"""
from __future__ import annotations

import numpy as np

from ..skeleton import LEAF_CARD_CORNERS

__all__ = ["LeafCards", "CLUSTER_AREA_GAIN", "cluster_axes"]

# Span of a uniform spread in standard deviations: a cluster card reaches as far as its leaves do.
_SPREAD_SPAN = 2.0 * np.sqrt(3.0)
# By default a cluster card covers this many times its leaves' estimated covered area (within their spread): from
# afar the gaps between a cluster's leaves close, so its outline is more than its leaf area. Chosen by the least
# LOD silhouette IoU against other gains (docs/library.md, "Levels of detail").
CLUSTER_AREA_GAIN = 1.5
# Grid cell sizes tried: the finest (span / 4096) times this factor to an integer power.
_CELL_STEP = 1.02
_FINEST_CELL = 1.0 / 4096


class LeafCards:
    """One tree's leaf cards, prepared once for any number of clusterings: corners (M, 4, 3), centres (M, 3) and
    areas (M,) float64 metres, and the occupied-cell count of every grid size tried so far.

    leaves : (M, 4, 4) float, each leaf's transform of the unit card.
    """

    def __init__(self, leaves: np.ndarray):
        self.leaves = np.asarray(leaves, np.float64)
        homo = np.concatenate([LEAF_CARD_CORNERS, np.ones((4, 1), np.float32)], axis=1).astype(np.float64)
        self.corners = np.einsum("mij,kj->mki", self.leaves, homo)[..., :3]
        self.centres = self.corners.mean(axis=1)
        self.areas = np.linalg.norm(np.cross(self.corners[:, 1] - self.corners[:, 0],
                                             self.corners[:, 3] - self.corners[:, 0]), axis=1)
        if len(self.leaves):
            self._low = self.centres.min(axis=0)
            self._span = float(np.max(self.centres.max(axis=0) - self._low)) + 1e-9
        self._counts: dict[int, int] = {}

    def __len__(self) -> int:
        return len(self.leaves)

    def _cell_size(self, step: int) -> float:
        return self._span * _FINEST_CELL * _CELL_STEP ** step

    def _cell_keys(self, step: int) -> np.ndarray:
        keys = np.floor((self.centres - self._low) / self._cell_size(step)).astype(np.int64)
        return keys[:, 0] * 4_000_037 ** 2 + keys[:, 1] * 4_000_037 + keys[:, 2]

    def _count(self, step: int) -> int:
        if step not in self._counts:
            self._counts[step] = len(np.unique(self._cell_keys(step)))
        return self._counts[step]

    def grid_labels(self, target: int) -> tuple[np.ndarray, float]:
        """(M,) int64 cluster label per leaf (occupied cells of the finest grid on the size ladder with at most
        `target` cells, numbered in sorted cell order) and that grid's cell size in metres."""
        # Bisection on the ladder (cell counts fall as cells grow, up to grid alignment), then the next sizes
        # until the count really is within the target.
        low, high = 0, int(np.ceil(np.log(4096 * 1.01) / np.log(_CELL_STEP)))
        while high - low > 1:
            mid = (low + high) // 2
            if self._count(mid) > target:
                low = mid
            else:
                high = mid
        step = high
        while self._count(step) > target:
            step += 1
        _, labels = np.unique(self._cell_keys(step), return_inverse=True)
        return labels.astype(np.int64), self._cell_size(step)

    def cluster(self, anchor: np.ndarray, n_clusters: int,
                area_gain: float = CLUSTER_AREA_GAIN) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Merge the leaves into at most `n_clusters` larger cards on a voxel grid (one card per occupied cell).

        anchor : (M,) int, node of each leaf. Returns (transforms (C, 4, 4) float32, card_node (C,) int32,
        merged (C,) bool: the card stands for more than one leaf, so it is drawn with a clump texture). A
        cluster's card hangs from the node of its leaf nearest the cluster centre; it is centred on the
        members, lies along their two widest spreads (`_fitted_cards`), and its area is the area the members
        cover together: sum of areas x (1 - exp(-d)) / d, with d their projected area (half their area, random
        orientation) over the cell's face, x `area_gain` (never beyond the members' spread). A cluster of one
        leaf is that leaf.
        """
        m = len(self)
        if m == 0 or n_clusters <= 0:
            return np.zeros((0, 4, 4), np.float32), np.zeros(0, np.int32), np.zeros(0, bool)
        centres = self.centres
        labels, cell = self.grid_labels(min(n_clusters, m))
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
        total = np.bincount(labels, weights=self.areas, minlength=n)
        d = 0.5 * total / (cell * cell)
        covered = np.where(count > 1, total * -np.expm1(-d) / np.maximum(d, 1e-12), total)
        cards = self.leaves[representative].copy()
        merged = count[labels] > 1
        if merged.any():
            fitted = _fitted_cards(self.corners[merged].reshape(-1, 3), np.repeat(labels[merged], 4), n,
                                   area_gain * covered)
            many = count > 1
            cards[many] = fitted[many]
        card_node = np.asarray(anchor)[representative]
        return cards.astype(np.float32), card_node.astype(np.int32), count > 1


def _fitted_cards(points: np.ndarray, labels: np.ndarray, n: int, area: np.ndarray) -> np.ndarray:
    """(n, 4, 4) float64 card transforms fitted to each cluster's points (P, 3) metres (labels (P,) int in
    [0, n)): centred on the points' mean, length along their principal axis, width along the second, normal
    along the least spread; length and width span the points as a uniform spread would (2 sqrt(3) std)."""
    mean, axes, variance = cluster_axes(points, labels, n, with_variance=True)
    span = _SPREAD_SPAN * np.sqrt(np.maximum(variance, 0.0))
    length, width = np.maximum(span[:, 2], 1e-4), np.maximum(span[:, 1], 1e-4)
    # The card's area is `area`, in the spread's proportions, never beyond the spread.
    shrink = np.minimum(np.sqrt(area / (length * width)), 1.0)
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


def cluster_axes(points: np.ndarray, labels: np.ndarray, n: int, with_variance: bool = False):
    """Each cluster's mean (n, 3) and principal axes (n, 3, 3) float64, columns by ascending spread (axes[:, :, 2]
    the principal axis), of points (P, 3) metres labelled (P,) int in [0, n); with `with_variance`, also the
    variances (n, 3) along those axes."""
    count = np.maximum(np.bincount(labels, minlength=n), 1).astype(np.float64)
    mean = np.stack([np.bincount(labels, weights=points[:, k], minlength=n) for k in range(3)], axis=1)
    mean /= count[:, None]
    rel = points - mean[labels]
    cov = np.empty((n, 3, 3))
    for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):  # symmetric: six sums, not nine
        cov[:, i, j] = cov[:, j, i] = np.bincount(labels, weights=rel[:, i] * rel[:, j], minlength=n)
    variance, axes = np.linalg.eigh(cov / count[:, None, None])
    return (mean, axes, variance) if with_variance else (mean, axes)
