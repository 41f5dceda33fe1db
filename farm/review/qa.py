"""Automatic QA flags for review: checks over the trees table's skeleton arrays and stats, and sketch ink.

Input: a pyarrow Table of trees rows (skeleton list columns, stats) and the sketches of its views; output: a
`QaFlags` table (tree_id, flag, value) of the flags raised. Vectorized over every tree of a batch at once.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from farm.dataset.image_codec import decode_map

__all__ = ["FLAGS", "QA_VERSION", "QaFlags", "tree_flags", "sketch_ink", "ink_flags", "TREE_COLUMNS",
           "BELOW_GROUND_M", "LEAF_FAR_FRACTION", "JUMP_FRACTION", "JUMP_TIMES_MEAN", "MIN_TRIANGLES",
           "HUGE_TRIANGLES", "HUGE_EXTENT_M", "MIN_INK"]

# name -> what the reviewer is told; `value` of each flag is in the unit named here.
FLAGS = {
    "below_ground": "branches below ground (value: lowest node z, m)",
    "leaves_outside_crown": "leaves far outside the crown (value: number of such leaves)",
    "disconnected": "disconnected parts: extra roots, bad parent/leaf links or long jumps (value: count)",
    "degenerate_mesh": "degenerate mesh: failed build, too few triangles, non-finite or tiny (value: triangles)",
    "huge_mesh": "huge mesh: too many triangles or too large (value: triangles)",
    "faint_sketch": "a sketch with almost no ink (value: lowest ink fraction over the views)",
}

# Bump when a check or threshold changes: cached flags of every batch are then computed again.
QA_VERSION = 1
# A node this far below z = 0 (or 2% of the tree's height, if more) is underground.
BELOW_GROUND_M = 0.05
# A leaf whose origin lies farther than this fraction of the tree height (or 1 m) from its own node, or
# outside the nodes' crown (radius and top) by that margin, is far outside the crown.
LEAF_FAR_FRACTION = 0.25
# A parent-child segment longer than this fraction of the height and this many times the tree's mean segment
# is a jump between disconnected parts.
JUMP_FRACTION = 0.35
JUMP_TIMES_MEAN = 10.0
MIN_TRIANGLES = 8
MIN_HEIGHT_M = 0.05
HUGE_TRIANGLES = 2_000_000
HUGE_EXTENT_M = 80.0
# Fraction of dark pixels (< 128) below which a sketch has almost no ink.
MIN_INK = 0.002

TREE_COLUMNS = ["tree_id", "positions", "parent", "leaves", "leaf_node", "height", "crown_radius",
                "bark_triangles", "leaf_triangles", "n_vertices", "error"]


@dataclass(frozen=True)
class QaFlags:
    """Raised flags, one entry per (tree, flag): tree_ids (K,) str, flags (K,) str, values (K,) float64."""

    tree_ids: list
    flags: list
    values: np.ndarray

    @staticmethod
    def empty() -> "QaFlags":
        return QaFlags([], [], np.zeros(0))

    def __add__(self, other: "QaFlags") -> "QaFlags":
        return QaFlags(self.tree_ids + other.tree_ids, self.flags + other.flags,
                       np.concatenate([self.values, other.values]))

    def rows(self) -> list[tuple[str, str, float]]:
        return list(zip(self.tree_ids, self.flags, self.values.tolist()))


def _flat_lists(column, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A list<...> column as (values (E, width), tree index per entry (E,), entries per tree (T,) int64)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    array = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    array = array.fill_null(pa.scalar([], array.type))
    values = pc.list_flatten(array).to_numpy(zero_copy_only=False)
    counts = pc.list_value_length(array).to_numpy(zero_copy_only=False).astype(np.int64) // width
    tree_of = np.repeat(np.arange(len(counts)), counts)
    return values.reshape(-1, width) if width > 1 else values, tree_of, counts


def _per_tree_max(values: np.ndarray, tree_of: np.ndarray, n_trees: int, empty: float) -> np.ndarray:
    out = np.full(n_trees, empty, np.float64)
    np.maximum.at(out, tree_of, values)
    return out


def _per_tree_min(values: np.ndarray, tree_of: np.ndarray, n_trees: int, empty: float) -> np.ndarray:
    out = np.full(n_trees, empty, np.float64)
    np.minimum.at(out, tree_of, values)
    return out


def _stat(table, name: str) -> np.ndarray:
    return table[name].to_numpy(zero_copy_only=False).astype(np.float64)


def tree_flags(table) -> QaFlags:
    """Flags from the skeleton arrays and stats of every row of `table` (a pyarrow Table with TREE_COLUMNS)."""
    n = table.num_rows
    if n == 0:
        return QaFlags.empty()
    tree_ids = table["tree_id"].to_pylist()
    failed = ~np.asarray(table["error"].is_null().to_numpy(zero_copy_only=False), bool)
    positions, node_tree, n_nodes = _flat_lists(table["positions"], 3)
    positions = positions.astype(np.float64)
    parent, _, _ = _flat_lists(table["parent"], 1)
    leaves, leaf_tree, n_leaves = _flat_lists(table["leaves"], 16)
    leaf_node, _, _ = _flat_lists(table["leaf_node"], 1)
    node_start = np.concatenate([[0], np.cumsum(n_nodes)[:-1]])
    height = np.nan_to_num(_stat(table, "height"), nan=0.0)
    triangles = np.nan_to_num(_stat(table, "bark_triangles") + _stat(table, "leaf_triangles"), nan=0.0)

    # below ground
    lowest = _per_tree_min(positions[:, 2], node_tree, n, 0.0)
    below = lowest < -np.maximum(BELOW_GROUND_M, 0.02 * height)

    # disconnected: roots other than node 0, parents not earlier nodes, leaves on missing nodes, long jumps
    local_index = np.arange(len(parent)) - node_start[node_tree]
    bad_parent = np.where(local_index == 0, parent != -1, (parent < 0) | (parent >= local_index))
    problems = np.bincount(node_tree[bad_parent], minlength=n).astype(np.float64)
    has_parent = (local_index > 0) & ~bad_parent
    child = np.flatnonzero(has_parent)
    segment = np.linalg.norm(positions[child] - positions[node_start[node_tree[child]] + parent[child]], axis=1)
    segment_tree = node_tree[child]
    mean_segment = (np.bincount(segment_tree, weights=segment, minlength=n)
                    / np.maximum(np.bincount(segment_tree, minlength=n), 1))
    jump = segment > np.maximum(JUMP_FRACTION * height, JUMP_TIMES_MEAN * mean_segment)[segment_tree]
    problems += np.bincount(segment_tree[jump], minlength=n)
    leaf_bad = (leaf_node < 0) | (leaf_node >= n_nodes[leaf_tree])
    problems += np.bincount(leaf_tree[leaf_bad], minlength=n)

    # leaves far outside the crown that the nodes span
    leaf_origin = leaves.reshape(-1, 4, 4)[:, :3, 3].astype(np.float64)
    node_radius = _per_tree_max(np.hypot(positions[:, 0], positions[:, 1]), node_tree, n, 0.0)
    node_top = _per_tree_max(positions[:, 2], node_tree, n, 0.0)
    margin = np.maximum(LEAF_FAR_FRACTION * height, 1.0)
    own_node = node_start[leaf_tree] + np.clip(leaf_node, 0, np.maximum(n_nodes[leaf_tree] - 1, 0))
    far = np.zeros(len(leaf_origin), bool)
    if len(positions):
        far = np.linalg.norm(leaf_origin - positions[np.minimum(own_node, len(positions) - 1)], axis=1) \
            > margin[leaf_tree]
    far |= np.hypot(leaf_origin[:, 0], leaf_origin[:, 1]) > (node_radius + margin)[leaf_tree]
    far |= (leaf_origin[:, 2] > (node_top + margin)[leaf_tree]) | (leaf_origin[:, 2] < -margin[leaf_tree])
    far_leaves = np.bincount(leaf_tree[far], minlength=n).astype(np.float64)

    # degenerate or huge meshes
    finite = np.bincount(node_tree[~np.isfinite(positions).all(axis=1)], minlength=n) == 0
    degenerate = failed | (triangles < MIN_TRIANGLES) | (height < MIN_HEIGHT_M) | ~finite | (n_nodes < 2)
    extent = np.maximum(height, np.nan_to_num(_stat(table, "crown_radius"), nan=0.0))
    huge = (triangles > HUGE_TRIANGLES) | (extent > HUGE_EXTENT_M)

    raised = {"below_ground": (below, lowest), "leaves_outside_crown": (far_leaves > 0, far_leaves),
              "disconnected": (problems > 0, problems), "degenerate_mesh": (degenerate, triangles),
              "huge_mesh": (huge, triangles)}
    out = QaFlags.empty()
    for name, (mask, value) in raised.items():
        hit = np.flatnonzero(mask)
        out = out + QaFlags([tree_ids[i] for i in hit], [name] * len(hit), value[hit].astype(np.float64))
    return out


def sketch_ink(png: bytes) -> float:
    """Fraction of dark pixels (< 128) of a sketch PNG (black lines on white)."""
    image = decode_map(png)
    return float(np.count_nonzero(image < 128)) / max(image.size, 1)


def ink_flags(tree_ids: list, sketches: list) -> QaFlags:
    """`faint_sketch` for trees whose least-inked view falls under MIN_INK.

    tree_ids : (V,) tree id of each view; sketches : (V,) PNG bytes (None where a view has no sketch).
    """
    lowest: dict[str, float] = {}
    for tree_id, png in zip(tree_ids, sketches):
        if png is not None:
            lowest[tree_id] = min(lowest.get(tree_id, 1.0), sketch_ink(png))
    faint = [(tree_id, ink) for tree_id, ink in lowest.items() if ink < MIN_INK]
    return QaFlags([t for t, _ in faint], ["faint_sketch"] * len(faint), np.array([v for _, v in faint], float))
