"""Grafting (thesis 003 Algorithms 5, 7, 8): a side anchor on a node, a subtree attached there, radii smoothed;
and the subtree under a node, as a mask or as a Skeleton of its own (what a graft copies).

In: Skeletons, node indices, a camera position. Out: new Skeletons (inputs are never changed).
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError
from ..geometry.radii import pipe_model_radii
from ..geometry.topology import depth_levels
from ..skeleton import Skeleton

__all__ = ["side_anchor", "graft", "smooth_radius", "pipe_smooth_radius", "subtree_mask", "extract_subtree"]

# Algorithm 5's constants: the anchor leans 0.3 toward the parent direction, is 0.6 of the first child's
# edge long, and 0.8 of the node's radius thick. Algorithm 7 smooths with ratio 0.8.
ANCHOR_LEAN, ANCHOR_LENGTH, ANCHOR_RADIUS, SMOOTH_RATIO = 0.3, 0.6, 0.8, 0.8


def _check_node(skeleton: Skeleton, node: int, key: str = "node") -> int:
    if isinstance(node, bool) or not isinstance(node, (int, np.integer)) or not 0 <= node < len(skeleton):
        raise ParameterError(key, node, f"a node index in [0, {len(skeleton) - 1}]")
    return int(node)


def _append(skeleton: Skeleton, positions, parent, radius, order, leaves=None, leaf_node=None) -> Skeleton:
    leaves = np.zeros((0, 4, 4), np.float32) if leaves is None else leaves
    leaf_node = np.zeros(0, np.int32) if leaf_node is None else leaf_node
    return Skeleton(positions=np.concatenate([skeleton.positions, np.reshape(positions, (-1, 3))]),
                    parent=np.concatenate([skeleton.parent, np.ravel(parent)]),
                    radius=np.concatenate([skeleton.radius, np.ravel(radius)]),
                    order=np.concatenate([skeleton.order, np.ravel(order)]),
                    leaves=np.concatenate([skeleton.leaves, leaves]),
                    leaf_node=np.concatenate([skeleton.leaf_node, leaf_node]))


def side_anchor(skeleton: Skeleton, node: int, camera_position, right: bool = True) -> tuple[Skeleton, int]:
    """Algorithm 5: a short side twig at `node` to graft onto; returns the new skeleton and the twig's node.

    The side is (toCamera x trunkDir) for the right, the reverse for the left, where trunkDir runs to the
    node's first child. camera_position : (3,) metres. The new node is appended (index len(skeleton)).
    """
    node = _check_node(skeleton, node)
    children = skeleton.children(node)
    if len(children) == 0:
        raise ParameterError("node", node, "a node with at least one child (Algorithm 5 follows its first child)")
    here = skeleton.positions[node].astype(np.float64)
    trunk = skeleton.positions[children[0]] - here
    length = float(np.linalg.norm(trunk))
    to_camera = np.asarray(camera_position, np.float64) - here
    if length == 0 or np.linalg.norm(to_camera) == 0:
        raise ParameterError("camera_position", list(np.asarray(camera_position, float)),
                             "a point away from the node, on a node whose first edge has a length")
    trunk /= length
    to_camera /= np.linalg.norm(to_camera)
    side = np.cross(to_camera, trunk) if right else np.cross(trunk, to_camera)
    if np.linalg.norm(side) < 1e-6:
        raise ParameterError("camera_position", list(np.asarray(camera_position, float)),
                             "a camera off the line of the node's first edge (the side direction is undefined)")
    side /= np.linalg.norm(side)
    direction = side + ANCHOR_LEAN * trunk
    direction /= np.linalg.norm(direction)
    anchor = len(skeleton)
    grown = _append(skeleton, here + direction * length * ANCHOR_LENGTH, node,
                    skeleton.radius[node] * ANCHOR_RADIUS, min(int(skeleton.order[node]) + 1, 255))
    return grown, anchor


def _rotation_between(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 3) the smallest rotation taking unit `source` to unit `target` (any half turn if they are opposite)."""
    axis = np.cross(source, target)
    sin, cos = np.linalg.norm(axis), float(np.dot(source, target))
    if sin < 1e-12:
        if cos > 0:
            return np.eye(3)
        perpendicular = np.cross(source, [1.0, 0.0, 0.0] if abs(source[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis, sin, cos = perpendicular / np.linalg.norm(perpendicular), 0.0, -1.0
    else:
        axis = axis / sin
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + sin * k + (1 - cos) * (k @ k)


def subtree_mask(skeleton: Skeleton, start: int) -> np.ndarray:
    """(N,) bool, `start` and every node below it (a level-by-level sweep, no per-node loop)."""
    start = _check_node(skeleton, start, "start")
    mask = np.zeros(len(skeleton), bool)
    mask[start] = True
    for idx in depth_levels(skeleton.depth, first=int(skeleton.depth[start]) + 1):
        mask[idx] = mask[skeleton.parent[idx]]
    return mask


def extract_subtree(skeleton: Skeleton, start: int) -> Skeleton:
    """The subtree under `start` as a Skeleton of its own: `start` becomes node 0 (at its own position, not
    moved), the nodes are renumbered in index order (parent[i] < i), leaves hanging on its nodes come along, and
    orders are shifted down by start's order (clipped at 0) so the subtree's root is order 0."""
    subtree = skeleton.subset(subtree_mask(skeleton, start))
    order = np.maximum(subtree.order.astype(np.int64) - int(skeleton.order[start]), 0)
    return Skeleton(positions=subtree.positions, parent=subtree.parent, radius=subtree.radius, order=order,
                    leaves=subtree.leaves, leaf_node=subtree.leaf_node)


def _with_radius(skeleton: Skeleton, radius: np.ndarray) -> Skeleton:
    return Skeleton(positions=skeleton.positions, parent=skeleton.parent, radius=radius, order=skeleton.order,
                    leaves=skeleton.leaves, leaf_node=skeleton.leaf_node)


def smooth_radius(skeleton: Skeleton, start: int, ratio: float = SMOOTH_RATIO) -> Skeleton:
    """Algorithm 8: every node below `start` gets radius[start] * ratio**(depth below start); ratio in (0, 1]."""
    if not 0 < ratio <= 1:
        raise ParameterError("ratio", ratio, "a factor in (0, 1]")
    mask = subtree_mask(skeleton, start)
    radius = skeleton.radius.astype(np.float64)
    relative_depth = skeleton.depth[mask] - skeleton.depth[start]
    radius[mask] = radius[start] * ratio ** relative_depth
    return _with_radius(skeleton, radius)


def pipe_smooth_radius(skeleton: Skeleton, start: int, exponent: float = 2.5) -> Skeleton:
    """The digest's default smoothing (3.7): pipe rule below `start` from the tips' own radii, each node then
    clamped to at most radius[start] (pipe radii never grow toward the tips, so every child <= its parent).
    `start` and everything outside its subtree keep their radii."""
    mask = subtree_mask(skeleton, start)
    nodes = np.flatnonzero(mask)  # ascending, so the local parent array keeps parent[i] < i
    local_index = np.full(len(skeleton), -1, np.int64)
    local_index[nodes] = np.arange(len(nodes))
    local_parent = local_index[skeleton.parent[nodes]]
    local_parent[0] = -1
    pipe = pipe_model_radii(local_parent, skeleton.radius[nodes], exponent)
    radius = skeleton.radius.copy()
    radius[nodes[1:]] = np.minimum(pipe[1:], skeleton.radius[start])
    return _with_radius(skeleton, radius)


def graft(skeleton: Skeleton, anchor: int, subtree: Skeleton, *, smoothing: str = "pipe",
          ratio: float = SMOOTH_RATIO, pipe_exponent: float = 2.5) -> Skeleton:
    """Algorithm 7: attach `subtree` at `anchor`, its first edge turned along the anchor's own edge.

    The subtree is moved to its root, rotated by the smallest turn taking its first F (root to node 1) to
    normalize(anchor - parent(anchor)), translated by exactly the anchor position (digest: the thesis's 1.001
    factor is dropped), and its root merged into the anchor. Its leaves move with it; orders are shifted by the
    anchor's order. smoothing : 'pipe' (digest default, `pipe_smooth_radius`) or 'ratio' (Algorithm 8 with
    `ratio`) from the anchor. The subtree's nodes are appended after the existing ones, in their own order.
    """
    anchor = _check_node(skeleton, anchor, "anchor")
    if anchor == 0:
        raise ParameterError("anchor", anchor, "a node with a parent (its edge gives the graft direction)")
    if len(subtree) < 2:
        raise ParameterError("subtree", repr(subtree), "a skeleton with at least one edge")
    if smoothing not in ("pipe", "ratio"):
        raise ParameterError("smoothing", smoothing, "'pipe' or 'ratio'")
    direction = skeleton.positions[anchor].astype(np.float64) - skeleton.positions[skeleton.parent[anchor]]
    forward = subtree.positions[1].astype(np.float64) - subtree.positions[0]
    if np.linalg.norm(direction) == 0 or np.linalg.norm(forward) == 0:
        raise ParameterError("anchor", anchor, "an anchor edge and a subtree first edge of non-zero length")
    rotation = _rotation_between(forward / np.linalg.norm(forward), direction / np.linalg.norm(direction))
    root, target = subtree.positions[0].astype(np.float64), skeleton.positions[anchor].astype(np.float64)
    moved = (subtree.positions[1:] - root) @ rotation.T + target

    base = len(skeleton)
    parent = np.where(subtree.parent[1:] == 0, anchor, base + subtree.parent[1:].astype(np.int64) - 1)
    order = np.minimum(subtree.order[1:].astype(np.int64) + skeleton.order[anchor], 255)
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = rotation, target - rotation @ root
    leaves = np.einsum("ij,mjk->mik", transform, subtree.leaves).astype(np.float32)
    leaf_node = np.where(subtree.leaf_node == 0, anchor, base + subtree.leaf_node.astype(np.int64) - 1)
    grown = _append(skeleton, moved, parent, subtree.radius[1:], order, leaves, leaf_node)
    if smoothing == "ratio":
        return smooth_radius(grown, anchor, ratio)
    return pipe_smooth_radius(grown, anchor, pipe_exponent)
