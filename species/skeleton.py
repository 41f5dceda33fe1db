"""The Skeleton: a tree as a structure of arrays (nodes, parents, radii, branch order, leaf placements).

Every growth model returns one; meshing, rendering, reconstruction and metrics consume it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from .errors import TreefarmError
from .geometry.topology import node_depths
from .geometry.vectors import column_bounds, row_norms

__all__ = ["Skeleton", "SkeletonError", "LEAF_CARD_CORNERS"]

# The unit leaf card in its own frame: width along x (centred), length along z from the stem, normal +y.
# A leaf transform maps these corners to world space; the transform carries the leaf's size.
LEAF_CARD_CORNERS = np.array(
    [[-0.5, 0.0, 0.0], [0.5, 0.0, 0.0], [0.5, 0.0, 1.0], [-0.5, 0.0, 1.0]], dtype=np.float32
)


class SkeletonError(TreefarmError):
    """A skeleton's arrays are inconsistent (shape, dtype, topology or values)."""


def _frozen(array: np.ndarray, dtype, name: str, shape_tail: tuple[int, ...]) -> np.ndarray:
    out = np.ascontiguousarray(np.asarray(array), dtype=dtype)
    if out.shape[1:] != shape_tail:
        raise SkeletonError(f"{name} must have shape (N, {', '.join(map(str, shape_tail))}); got {out.shape}")
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Skeleton:
    """A tree skeleton in the world frame (Z up, metres, base at the origin).

    positions : (N, 3) float32, metres, Z up. Node 0 is the root at the base of the trunk.
    parent    : (N,) int32, index of each node's parent; -1 for the root only. Parents come before their
                children (parent[i] < i), so a reverse sweep visits tips before the root.
    radius    : (N,) float32, metres, branch radius at each node (> 0).
    order     : (N,) uint8, branch order: 0 = trunk, 1 = branches on the trunk, ...
    leaves    : (M, 4, 4) float32, leaf placements: each maps the unit card LEAF_CARD_CORNERS (width along x,
                length along z, normal +y) to world space, size included.
    leaf_node : (M,) int32, the node each leaf hangs from.

    Arrays are read-only; derived views are cached properties.
    """

    positions: np.ndarray
    parent: np.ndarray
    radius: np.ndarray
    order: np.ndarray
    leaves: np.ndarray = field(default_factory=lambda: np.zeros((0, 4, 4), np.float32))
    leaf_node: np.ndarray = field(default_factory=lambda: np.zeros((0,), np.int32))

    def __post_init__(self) -> None:
        positions = _frozen(self.positions, np.float32, "positions", (3,))
        n = len(positions)
        parent = _frozen(self.parent, np.int32, "parent", ())
        radius = _frozen(self.radius, np.float32, "radius", ())
        order = _frozen(self.order, np.uint8, "order", ())
        leaves = _frozen(np.reshape(self.leaves, (-1, 4, 4)), np.float32, "leaves", (4, 4))
        leaf_node = _frozen(self.leaf_node, np.int32, "leaf_node", ())
        for name, arr in (("parent", parent), ("radius", radius), ("order", order)):
            if len(arr) != n:
                raise SkeletonError(f"{name} has {len(arr)} entries but positions has {n}")
        if len(leaf_node) != len(leaves):
            raise SkeletonError(f"leaf_node has {len(leaf_node)} entries but leaves has {len(leaves)}")
        if n == 0:
            raise SkeletonError("a skeleton needs at least one node (the root)")
        if parent[0] != -1:
            raise SkeletonError(f"node 0 must be the root (parent -1); its parent is {parent[0]}")
        if n > 1:
            rest = parent[1:]
            bad = np.flatnonzero((rest < 0) | (rest >= np.arange(1, n)))
            if len(bad):
                i = int(bad[0]) + 1
                raise SkeletonError(
                    f"parent[{i}] = {parent[i]}: every non-root node needs a parent index in [0, {i - 1}]"
                )
        if not np.all(np.isfinite(positions)):
            raise SkeletonError("positions contain NaN or infinity")
        if not np.all(np.isfinite(radius)) or np.any(radius <= 0):
            i = int(np.flatnonzero(~(radius > 0))[0]) if np.any(~(radius > 0)) else 0
            raise SkeletonError(f"radius[{i}] = {radius[i]}: radii must be finite and > 0")
        if len(leaf_node) and (leaf_node.min() < 0 or leaf_node.max() >= n):
            raise SkeletonError(f"leaf_node values must be node indices in [0, {n - 1}]")
        if not np.all(np.isfinite(leaves)):
            raise SkeletonError("leaf transforms contain NaN or infinity")
        for name, arr in (("positions", positions), ("parent", parent), ("radius", radius),
                          ("order", order), ("leaves", leaves), ("leaf_node", leaf_node)):
            object.__setattr__(self, name, arr)

    # ----------------------------------------------------------------- sizes
    def __len__(self) -> int:
        return len(self.positions)

    @property
    def n_nodes(self) -> int:
        return len(self.positions)

    @property
    def n_leaves(self) -> int:
        return len(self.leaves)

    # ------------------------------------------------------------- topology
    @cached_property
    def n_children(self) -> np.ndarray:
        """(N,) int32, number of children of each node."""
        return np.bincount(self.parent[1:], minlength=len(self)).astype(np.int32)

    @cached_property
    def _children_csr(self) -> tuple[np.ndarray, np.ndarray]:
        child_ids = np.arange(1, len(self), dtype=np.int32)
        sort = np.argsort(self.parent[1:], kind="stable")
        offsets = np.zeros(len(self) + 1, np.int32)
        np.cumsum(self.n_children, out=offsets[1:])
        return offsets, child_ids[sort]

    def children(self, node: int) -> np.ndarray:
        """Indices of the children of `node`, ascending."""
        offsets, ids = self._children_csr
        return ids[offsets[node]:offsets[node + 1]]

    @cached_property
    def tips(self) -> np.ndarray:
        """(T,) int32, nodes without children."""
        return np.flatnonzero(self.n_children == 0).astype(np.int32)

    @cached_property
    def depth(self) -> np.ndarray:
        """(N,) int32, number of edges from the root (`geometry.topology.node_depths`)."""
        return node_depths(self.parent)

    @cached_property
    def segment_lengths(self) -> np.ndarray:
        """(N,) float32, metres, length of the edge from each node's parent to it (0 for the root)."""
        lengths = np.zeros(len(self), np.float32)
        lengths[1:] = row_norms(self.positions[1:] - self.positions[self.parent[1:]])
        return lengths

    @cached_property
    def continuation(self) -> np.ndarray:
        """(N,) int32, the child that continues each node's branch, or -1 at a branch end.

        The continuing child is the child of the same order with the largest radius (lowest index on ties);
        every other child starts a new branch at its parent node.
        """
        cont = np.full(len(self), -1, np.int32)
        if len(self) < 2:
            return cont
        child = np.arange(1, len(self), dtype=np.int32)
        par = self.parent[1:]
        same = self.order[child] == self.order[par]
        child, par = child[same], par[same]
        # Sort by (parent, -radius, index) and keep the first child per parent.
        keys = np.lexsort((child, -self.radius[child], par))
        child, par = child[keys], par[keys]
        first = np.ones(len(par), bool)
        first[1:] = par[1:] != par[:-1]
        cont[par[first]] = child[first]
        return cont

    @cached_property
    def branch_starts(self) -> np.ndarray:
        """(B,) int32, the first node of each branch (nodes that do not continue their parent's branch)."""
        starts = np.ones(len(self), bool)
        cont = self.continuation
        starts[cont[cont >= 0]] = False
        return np.flatnonzero(starts).astype(np.int32)

    @cached_property
    def branch_id(self) -> np.ndarray:
        """(N,) int32, the branch each node belongs to; branches are numbered by their first node."""
        starts = np.zeros(len(self), bool)
        starts[self.branch_starts] = True
        ids = np.full(len(self), -1, np.int32)
        ids[starts] = np.arange(int(starts.sum()), dtype=np.int32)
        # Propagate along continuations: parents precede children, so repeated gathers converge.
        owner = np.where(starts, np.arange(len(self)), self.parent).astype(np.int32)
        owner[0] = 0
        while True:
            nxt = np.where(starts[owner], owner, owner[owner])
            if np.array_equal(nxt, owner):
                break
            owner = nxt
        return ids[owner]

    @cached_property
    def branch_parent(self) -> np.ndarray:
        """(B,) int64, the branch each branch grows from (-1 for the trunk)."""
        junction = self.parent[self.branch_starts]
        return np.where(junction >= 0, self.branch_id[np.maximum(junction, 0)], -1).astype(np.int64)

    @cached_property
    def branch_path_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """Every branch path (see `branch_paths`) end to end: (K,) int32 node indices and (B + 1,) int64 offsets,
        branch `b` being nodes[offsets[b]:offsets[b + 1]]."""
        bid = self.branch_id
        n_branches = int(bid.max()) + 1
        order = np.lexsort((self.depth, bid))
        bounds = np.searchsorted(bid[order], np.arange(n_branches + 1))
        first_parent = self.parent[order[bounds[:-1]]]
        joined = first_parent >= 0  # the branch starts at its junction node on the parent branch
        nodes = np.insert(order, bounds[:-1][joined], first_parent[joined]).astype(np.int32)
        offsets = (bounds + np.concatenate([[0], np.cumsum(joined)])).astype(np.int64)
        return nodes, offsets

    @cached_property
    def branch_paths(self) -> list[np.ndarray]:
        """Node indices of each branch in growth order, branch `b` at index `b`.

        A branch that grows out of another starts with its junction node on the parent branch, so
        consecutive entries of each path are always joined by an edge.
        """
        nodes, offsets = self.branch_path_nodes
        return np.split(nodes, offsets[1:-1])

    @property
    def n_branches(self) -> int:
        return int(self.branch_id.max()) + 1

    # ------------------------------------------------------------- measures
    @cached_property
    def total_length(self) -> float:
        """Metres of branch summed over the whole skeleton."""
        return float(self.segment_lengths.sum(dtype=np.float64))

    @cached_property
    def height(self) -> float:
        """Metres from the ground (z = 0) to the highest node or leaf corner."""
        top = float(self.positions[:, 2].max())
        if self.n_leaves:
            top = max(top, float(self.leaf_corners()[..., 2].max()))
        return top

    @cached_property
    def crown_radius(self) -> float:
        """Metres from the trunk axis (z) to the farthest node or leaf corner, horizontally."""
        pts = self.positions[:, :2]
        if self.n_leaves:
            pts = np.concatenate([pts, self.leaf_corners()[..., :2].reshape(-1, 2)])
        return float(np.sqrt((pts.astype(np.float64) ** 2).sum(axis=1).max()))

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float32, min and max corner over nodes (grown by their radius) and leaf corners."""
        r = self.radius[:, None]
        lo, hi = column_bounds(self.positions - r)[0], column_bounds(self.positions + r)[1]
        if self.n_leaves:
            corner_lo, corner_hi = column_bounds(self.leaf_corners().reshape(-1, 3))
            lo, hi = np.minimum(lo, corner_lo), np.maximum(hi, corner_hi)
        return np.stack([lo, hi]).astype(np.float32)

    def leaf_corners(self) -> np.ndarray:
        """(M, 4, 3) float32, world positions of each leaf card's four corners."""
        # (M, 3, 4) by one (3M, 3) @ (3, 4) product: the same values, faster than a stack of M small products.
        linear = (self.leaves[:, :3, :3].reshape(-1, 3) @ LEAF_CARD_CORNERS.T).reshape(-1, 3, 4)
        return (linear.transpose(0, 2, 1) + self.leaves[:, None, :3, 3]).astype(np.float32)

    def order_counts(self) -> np.ndarray:
        """(max_order + 1,) int64, number of branches of each order."""
        return np.bincount(self.order[self.branch_starts], minlength=int(self.order.max()) + 1)

    # ------------------------------------------------------------- editing
    def subset(self, keep) -> "Skeleton":
        """The skeleton of the nodes where `keep` ((N,) bool) is True, renumbered in index order (so still
        parent[i] < i). The first kept node becomes the root; every other kept node's parent must be kept.
        Leaves hanging on dropped nodes are dropped; positions, radii and orders are kept as they are."""
        keep = np.asarray(keep)
        if keep.dtype != bool or keep.shape != (len(self),):
            raise SkeletonError(f"keep must be a ({len(self)},) bool mask; got {keep.dtype} of shape {keep.shape}")
        nodes = np.flatnonzero(keep)
        if len(nodes) == 0:
            raise SkeletonError("keep selects no node: a skeleton needs at least one (the root)")
        new_index = np.full(len(self), -1, np.int64)
        new_index[nodes] = np.arange(len(nodes))
        parent = new_index[self.parent[nodes]]
        parent[0] = -1
        orphans = np.flatnonzero(parent[1:] < 0)
        if len(orphans):
            node = int(nodes[orphans[0] + 1])
            raise SkeletonError(f"keep drops node {self.parent[node]} but keeps its child {node}: allowed masks "
                                "that keep the parent of every kept node but the first")
        kept_leaves = keep[self.leaf_node]
        return Skeleton(positions=self.positions[nodes], parent=parent, radius=self.radius[nodes],
                        order=self.order[nodes], leaves=self.leaves[kept_leaves],
                        leaf_node=new_index[self.leaf_node[kept_leaves]])

    # ---------------------------------------------------------------- I/O
    def save(self, path: str | Path) -> None:
        """Write the arrays to an uncompressed `.npz` file."""
        np.savez(path, positions=self.positions, parent=self.parent, radius=self.radius, order=self.order,
                 leaves=self.leaves, leaf_node=self.leaf_node)

    @classmethod
    def load(cls, path: str | Path) -> "Skeleton":
        with np.load(path) as data:
            return cls(**{k: data[k] for k in ("positions", "parent", "radius", "order", "leaves", "leaf_node")})

    def to_arrays(self) -> dict[str, np.ndarray]:
        """The stored arrays by name (what a dataset row or an npz holds)."""
        return {"positions": self.positions, "parent": self.parent, "radius": self.radius,
                "order": self.order, "leaves": self.leaves, "leaf_node": self.leaf_node}

    def __repr__(self) -> str:
        return (f"Skeleton(nodes={len(self)}, branches={self.n_branches}, leaves={self.n_leaves}, "
                f"height={self.height:.2f} m, crown_radius={self.crown_radius:.2f} m)")
