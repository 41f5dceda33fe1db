"""Assembling grown Weber-Penn levels into one Skeleton: nodes sorted by (spline, step), parents before children,
every stem joined to its parent's node and every leaf hung on the node it grew from.

In: a `WeberPennTree` (the grown levels and the leaf transforms). Out: a `Skeleton`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TreefarmError
from ..skeleton import Skeleton
from .stems import Level

__all__ = ["WeberPennTree", "SkeletonAssemblyError", "assemble", "node_key", "MIN_RADIUS"]

MIN_RADIUS = 1e-4  # metres; Sapling allows 0 at tips, a skeleton needs > 0
# A node's key is spline * this + u; u is at most curveRes (<= 64), so keys of different splines never meet.
_SPLINE_KEY_STRIDE = 256.0
# Keys that differ by no more than this are the same node (u is a sum of a step and a fraction).
_KEY_TOLERANCE = 1e-9


class SkeletonAssemblyError(TreefarmError):
    """Grown stems that cannot be joined into one skeleton: a leaf or a stem start that matches no node."""


@dataclass
class WeberPennTree:
    """The grown tree before assembly: all stem points of all levels plus leaf transforms."""

    levels: list             # of Level, by branch order
    leaves: np.ndarray       # (M, 4, 4) leaf transforms
    leaf_spline: np.ndarray  # (M,) int, the spline id each leaf grew on
    leaf_u: np.ndarray       # (M,) position on that spline in segment steps


def node_key(spline, u) -> np.ndarray:
    """Sort key of the node at step `u` of spline `spline` (arrays or scalars): spline-major, then u."""
    return np.asarray(spline, np.float64) * _SPLINE_KEY_STRIDE + np.asarray(u, np.float64)


@dataclass(frozen=True)
class _NodeIndex:
    """Node ids by (spline, u), with each split's unowned first point aliased to its parent's node."""

    keys: np.ndarray        # (N,) sorted node keys; a node's id is its index
    alias_keys: np.ndarray  # (A,) sorted keys of split start points
    alias_nodes: np.ndarray  # (A,) int, the node each of them is (-1 where that matches no node either)

    def find(self, spline, u) -> np.ndarray:
        """(Q,) int node ids at (spline, u), through the aliases; -1 where none matches."""
        wanted = node_key(spline, u)
        nodes = _exact(self.keys, wanted)
        missing = nodes < 0
        if missing.any() and len(self.alias_keys):
            alias = _exact(self.alias_keys, wanted[missing])
            nodes[missing] = np.where(alias >= 0, self.alias_nodes[np.maximum(alias, 0)], -1)
        return nodes


def _exact(sorted_keys: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """(Q,) int index of each wanted key in `sorted_keys`, -1 where it is not there."""
    if len(sorted_keys) == 0:
        return np.full(len(wanted), -1, np.int64)
    index = np.minimum(np.searchsorted(sorted_keys, wanted), len(sorted_keys) - 1)
    found = np.isclose(sorted_keys[index], wanted, rtol=0, atol=_KEY_TOLERANCE)
    return np.where(found, index, -1)


def assemble(tree: WeberPennTree) -> Skeleton:
    """Turn stem point grids into one Skeleton: nodes sorted by (spline, position), parents before children."""
    spline, u, positions, radius = _node_candidates(tree.levels)
    keys, first = np.unique(node_key(spline, u), return_index=True)  # sorted; duplicates keep the first
    spline, positions, radius = spline[first], positions[first], radius[first]
    index = _NodeIndex(keys, *_split_aliases(tree.levels, keys))
    parent = _parents(tree.levels, spline, index)
    order = _order_of_splines(tree.levels)[spline]
    leaf_node = _leaf_nodes(tree, index)
    return Skeleton(positions=positions, parent=parent, radius=np.maximum(radius, MIN_RADIUS), order=order,
                    leaves=tree.leaves, leaf_node=leaf_node)


def _owned_points(level: Level) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(spline id, u, position, radius) of the points a level's splines own: a split's first point is its
    parent's node, a sprouted stem's first point is its collar, the trunk owns all of its points."""
    rows, steps = np.nonzero(level.valid)
    after_start = steps > level.first_step[rows]
    at_start = steps == level.first_step[rows]
    keep = after_start | (at_start & (level.collar[rows] | (level.parent_spline[rows] < 0)))
    rows, steps = rows[keep], steps[keep]
    positions = level.points[rows, steps]
    at_collar = level.collar[rows] & (steps == level.first_step[rows])
    positions[at_collar] = level.collar_points[rows[at_collar]]
    return level.spline_id[rows], steps.astype(np.float64), positions, level.radii[rows, steps]


def _node_candidates(levels: list) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(spline id, u, position, radius) of every node before duplicates are merged: each level's own points,
    then the points where sprouted stems leave their parents' axes (nodes of the parent splines)."""
    owned = [_owned_points(level) for level in levels]
    attached = [(level.parent_spline[level.collar], level.parent_u[level.collar],
                 level.attach_points[level.collar], level.attach_radii[level.collar]) for level in levels]
    return tuple(np.concatenate([part[i] for part in owned] + [part[i] for part in attached]) for i in range(4))


def _split_aliases(levels: list, node_keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A,) sorted keys of every split's start point and (A,) the node on its parent spline each one is."""
    spline_keys, parent_keys = [], []
    for level in levels:
        split = (~level.collar) & (level.parent_spline >= 0)
        spline_keys.append(node_key(level.spline_id[split], level.first_step[split]))
        parent_keys.append(node_key(level.parent_spline[split], level.parent_u[split]))
    alias_keys = np.concatenate(spline_keys)
    alias_nodes = _exact(node_keys, np.concatenate(parent_keys))
    by_key = np.argsort(alias_keys)
    return alias_keys[by_key], alias_nodes[by_key]


def _order_of_splines(levels: list) -> np.ndarray:
    """(max spline id + 1,) int64, branch order by spline id."""
    order = np.zeros(int(max(np.max(level.spline_id) for level in levels)) + 1, np.int64)
    for level_order, level in enumerate(levels):
        order[level.spline_id] = level_order
    return order


def _parents(levels: list, spline: np.ndarray, index: _NodeIndex) -> np.ndarray:
    """(N,) int64 parent of each node: the previous node of its spline, or for a spline's first node the node
    on the parent spline it starts from (-1 for the trunk's root)."""
    n_nodes = len(spline)
    parent = np.arange(-1, n_nodes - 1, dtype=np.int64)
    first_nodes = np.flatnonzero(np.concatenate([[True], spline[1:] != spline[:-1]]))
    spline_ids = np.concatenate([level.spline_id for level in levels])
    parent_spline_of = np.full(int(spline_ids.max()) + 1, -1, np.int64)
    parent_u_of = np.zeros(int(spline_ids.max()) + 1)
    parent_spline_of[spline_ids] = np.concatenate([level.parent_spline for level in levels])
    parent_u_of[spline_ids] = np.concatenate([level.parent_u for level in levels])
    starts = spline[first_nodes]
    has_parent = parent_spline_of[starts] >= 0
    junction = np.full(len(first_nodes), -1, np.int64)
    junction[has_parent] = index.find(parent_spline_of[starts][has_parent], parent_u_of[starts][has_parent])
    unmatched = np.flatnonzero(has_parent & (junction < 0))
    if len(unmatched):
        stem = int(starts[unmatched[0]])
        raise SkeletonAssemblyError(
            f"spline {stem} starts at step {parent_u_of[stem]:g} of spline {int(parent_spline_of[stem])}, where "
            f"that spline has no node; every stem must start on a node of its parent spline")
    parent[first_nodes] = junction
    return parent


def _leaf_nodes(tree: WeberPennTree, index: _NodeIndex) -> np.ndarray:
    """(M,) int64, the node each leaf hangs on: the node at the segment start below it on its spline."""
    if len(tree.leaves) == 0:
        return np.zeros(0, np.int64)
    step = np.floor(tree.leaf_u)
    nodes = index.find(tree.leaf_spline, step)
    unmatched = np.flatnonzero(nodes < 0)
    if len(unmatched):
        leaf = int(unmatched[0])
        raise SkeletonAssemblyError(
            f"leaf {leaf} (of {len(nodes)}) grew on spline {int(tree.leaf_spline[leaf])} at u = "
            f"{float(tree.leaf_u[leaf]):g}, but that spline has no node at step {float(step[leaf]):g} (nor does a "
            f"split start alias one there); every leaf must hang on a node of the spline it grew on")
    return nodes
