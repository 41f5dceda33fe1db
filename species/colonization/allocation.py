"""Resource allocation over a growing tree: extended Borchert-Honda and the priority model (digest 1.5, 1.6).

In: a parent array, axis flags, and the light Q each bud collected. Out: the resource v each bud receives.
Sweeps are vectorized by pointer jumping (ancestors at 2^j hops): O(N log depth), no loop over nodes.
"""
from __future__ import annotations

import numpy as np

__all__ = ["jump_tables", "subtree_sums", "path_products", "allocate", "priority_weights",
           "OMEGA_MAX", "OMEGA_MIN"]

OMEGA_MAX = 1.0    # priority of the first-ranked item (thesis, given)
OMEGA_MIN = 0.006  # priority of items ranked past kappa * N (thesis, given)


def jump_tables(parent: np.ndarray) -> list[np.ndarray]:
    """Ancestor tables: table j maps each node to its ancestor 2^j hops up, or to N past the root.

    parent : (N,) int, -1 for the root. Returns a list of (N,) int64 arrays, as long as the deepest path needs.
    """
    n = len(parent)
    up = np.where(parent >= 0, parent, n).astype(np.int64)
    tables = []
    while (up < n).any():
        tables.append(up)
        up = np.append(up, n)[up]
    return tables


def subtree_sums(tables: list[np.ndarray], values: np.ndarray) -> np.ndarray:
    """(N,) float64: each node's value plus the values of all its descendants (tips-to-root accumulation)."""
    n = len(values)
    total = np.asarray(values, np.float64).copy()
    for up in tables:
        # After this pass `total` covers descendants up to 2^(j+1) - 1 hops below each node.
        total = total + np.bincount(up, weights=total, minlength=n + 1)[:n]
    return total


def path_products(tables: list[np.ndarray], factors: np.ndarray) -> np.ndarray:
    """(N,) float64: the product of `factors` over each node and all its ancestors (root-to-tips allocation)."""
    product = np.asarray(factors, np.float64).copy()
    for up in tables:
        product = product * np.append(product, 1.0)[up]
    return product


def priority_weights(rank: np.ndarray, group_size: np.ndarray, kappa: float) -> np.ndarray:
    """Eq. 2.6: omega for 1-based `rank` among `group_size` items; linear from OMEGA_MAX down to kappa*N."""
    cut = kappa * group_size
    ramp = OMEGA_MAX - (OMEGA_MAX - OMEGA_MIN) * rank / np.maximum(cut, 1e-12)
    return np.where(rank <= cut, ramp, OMEGA_MIN)


def _share(weight: np.ndarray, group: np.ndarray, n_groups: int) -> np.ndarray:
    total = np.bincount(group, weights=weight, minlength=n_groups)[group]
    return np.divide(weight, total, out=np.zeros_like(weight), where=total > 0)


def allocate(parent: np.ndarray, node_lateral: np.ndarray, node_axis: np.ndarray, bud_host: np.ndarray,
             bud_apical: np.ndarray, bud_light: np.ndarray, *, model: str, alpha: float, lam: float,
             kappa: float, tables: list[np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The resource v of every bud, and Q accumulated in every node's subtree.

    parent       : (N,) int, -1 for the root (node 0), parent[i] < i.
    node_lateral : (N,) bool, the node starts a new axis (a lateral branch); the root counts as one.
    node_axis    : (N,) int, the start node of each node's axis.
    bud_host     : (B,) int, node each bud sits on; bud_apical (B,) bool, the bud continues its axis.
    bud_light    : (B,) float, Q, the light (or space) each bud collected this step, >= 0.
    model        : "borchert_honda" (split lam : 1-lam between main axis and laterals at every node) or
                   "priority" (rank the items along each axis, eq. 2.5-2.6, apical bud first).
    Returns v (B,) float64 in internode lengths and subtree Q (N,) float64. The root pool is alpha * Q_base.
    """
    n = len(parent)
    tables = jump_tables(parent) if tables is None else tables
    bud_light = np.asarray(bud_light, np.float64)
    subtree_light = subtree_sums(tables, np.bincount(bud_host, weights=bud_light, minlength=n))
    pool = alpha * subtree_light[0]
    node_factor = np.ones(n)
    child = np.arange(1, n)
    if model == "borchert_honda":
        # Items at each node: its child nodes and its buds, the main one weighted lam, laterals 1 - lam.
        child_weight = np.where(node_lateral[1:], 1.0 - lam, lam) * subtree_light[1:]
        bud_weight = np.where(bud_apical, lam, 1.0 - lam) * bud_light
        weight = np.concatenate([child_weight, bud_weight])
        group = np.concatenate([parent[1:], bud_host]).astype(np.int64)
        share = _share(weight, group, n)
        node_factor[1:] = share[: n - 1]
        bud_share = share[n - 1:]
    elif model == "priority":
        bud_count = subtree_sums(tables, np.bincount(bud_host, minlength=n))
        branch = child[node_lateral[1:]]
        light = np.concatenate([subtree_light[branch], bud_light])
        mean_light = np.concatenate([subtree_light[branch] / np.maximum(bud_count[branch], 1), bud_light])
        apical = np.concatenate([np.zeros(len(branch), bool), bud_apical])
        group = np.concatenate([node_axis[parent[branch]], node_axis[bud_host]]).astype(np.int64)
        order = np.lexsort((np.arange(len(group)), -mean_light, ~apical, group))
        sorted_group = group[order]
        first = np.searchsorted(sorted_group, sorted_group, side="left")
        rank = np.empty(len(group))
        rank[order] = np.arange(len(group)) - first + 1
        size = np.bincount(group, minlength=n)[group]
        share = _share(light * priority_weights(rank, size, kappa), group, n)
        node_factor[branch] = share[: len(branch)]
        bud_share = share[len(branch):]
    else:
        raise ValueError(f"unknown allocation model {model!r}")
    node_resource = pool * path_products(tables, node_factor)
    return node_resource[bud_host] * bud_share, subtree_light
