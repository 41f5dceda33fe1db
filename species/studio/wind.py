"""Wind data for engine shaders: per-vertex branch level, normalised distance along the branch, a phase per
branch and the branch's pivot, from the skeleton that made the mesh.

In: a Skeleton and vertex positions with their branch (bark) or node (leaves). Out: `_WIND` (V, 4) float32 and
`_WIND_PIVOT` (V, 3) float32, layout documented in WIND_LAYOUT.
"""
from __future__ import annotations

import numpy as np

from ..skeleton import Skeleton

__all__ = ["WIND_LAYOUT", "branch_pivots", "branch_reaches", "branch_phases", "wind_attributes",
           "GOLDEN_RATIO_CONJUGATE"]

WIND_LAYOUT = {
    "_WIND": "VEC4 float: x = branch level (0 trunk, 1 first-order branches, ...), y = normalised distance "
             "along the branch from its pivot (0 at the pivot, 1 at its far end), z = phase of the branch in "
             "[0, 1) (constant along a branch), w = branch level of the parent branch (-1 on the trunk)",
    "_WIND_PIVOT": "VEC3 float, metres: the branch's pivot (where it leaves its parent branch; the trunk's "
                   "base), in the file's own frame (Y up in glTF, Z up in USD)",
}
# Phases spread evenly by the golden-ratio sequence of the pivot node's index: deterministic, no two
# neighbouring branches in step, and the same branch gets the same phase in every level of detail.
GOLDEN_RATIO_CONJUGATE = 0.6180339887498949


def branch_pivots(skeleton: Skeleton) -> np.ndarray:
    """(B,) int64, node index of each branch's pivot: its junction on the parent branch (node 0 for the trunk)."""
    starts = skeleton.branch_starts.astype(np.int64)
    return np.where(skeleton.parent[starts] >= 0, skeleton.parent[starts], starts)


def branch_reaches(skeleton: Skeleton) -> np.ndarray:
    """(B,) float64 metres: straight distance from each branch's pivot to its farthest node."""
    pivot_xyz = skeleton.positions[branch_pivots(skeleton)].astype(np.float64)
    reach = np.linalg.norm(skeleton.positions - pivot_xyz[skeleton.branch_id], axis=1)
    branch_reach = np.zeros(skeleton.n_branches)
    np.maximum.at(branch_reach, skeleton.branch_id, reach)
    return branch_reach


def branch_phases(pivot_keys: np.ndarray) -> np.ndarray:
    """(B,) float32 in [0, 1): the phase of branches identified by integer keys (B,) (their LOD0 start node)."""
    return np.mod(np.asarray(pivot_keys, np.float64) * GOLDEN_RATIO_CONJUGATE, 1.0).astype(np.float32)


def wind_attributes(skeleton: Skeleton, positions: np.ndarray, branch: np.ndarray,
                    branch_keys: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Wind attributes of vertices.

    skeleton    : the skeleton the vertices were meshed from.
    positions   : (V, 3) float, metres, Z up.
    branch      : (V,) int, branch id of each vertex (bark `branch` attribute, or branch_id[node] for leaves).
    branch_keys : (B,) int, a stable key per branch for its phase (default: its start node); LODs pass the
                  LOD0 start node so a branch sways in step at every level.
    Returns (_WIND (V, 4) float32, _WIND_PIVOT (V, 3) float32 metres Z up). Distance along a branch is the
    straight distance from its pivot over the farthest node's, clipped to [0, 1].
    """
    branch = np.asarray(branch, np.int64)
    pivots = branch_pivots(skeleton)
    pivot_xyz = skeleton.positions[pivots].astype(np.float64)
    branch_reach = branch_reaches(skeleton)
    keys = skeleton.branch_starts if branch_keys is None else branch_keys
    phase = branch_phases(keys)
    level = skeleton.order[skeleton.branch_starts].astype(np.float32)
    parent_branch = np.where(pivots != skeleton.branch_starts, skeleton.branch_id[pivots], -1)
    parent_level = np.where(parent_branch >= 0, level[np.maximum(parent_branch, 0)], -1.0)
    along = np.linalg.norm(np.asarray(positions, np.float64) - pivot_xyz[branch], axis=1)
    along = np.clip(along / np.maximum(branch_reach[branch], 1e-9), 0.0, 1.0)
    wind = np.stack([level[branch], along, phase[branch], parent_level[branch]], axis=1).astype(np.float32)
    return wind, pivot_xyz[branch].astype(np.float32)
