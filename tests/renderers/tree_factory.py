"""Test trees for the renderer tests: a hand-built Skeleton and a matching TreeMesh of tapered tubes and leaf quads.

Used where the real generator and mesher are not wanted (fixed, small, fast); `make_tree(rng, ...)` -> (TreeMesh, Skeleton).
"""
from __future__ import annotations

import numpy as np

from species.skeleton import Skeleton
from species.tree_mesh import MeshPart, TreeMesh


def _branch(start: np.ndarray, direction: np.ndarray, length: float, n: int, droop: float,
            rng: np.random.Generator) -> np.ndarray:
    """(n, 3) node positions of a gently curving branch after `start` (start itself excluded)."""
    direction = direction / np.linalg.norm(direction)
    t = np.arange(1, n + 1)[:, None] / n
    bend = np.array([0.0, 0.0, -droop]) * t ** 2
    wobble = rng.normal(0.0, 0.01 * length, (n, 3)).cumsum(axis=0)
    return start + direction * length * t + bend * length + wobble


def make_skeleton(rng: np.random.Generator, height: float = 6.0, n_branches: int = 8, n_twigs: int = 3,
                  nodes_per_branch: int = 8, leaves_per_twig: int = 6) -> Skeleton:
    """A three-order skeleton: a trunk, `n_branches` order-1 branches, `n_twigs` order-2 twigs on each."""
    positions = [np.zeros((1, 3))]
    parent = [np.array([-1])]
    radius = [np.array([0.04 * height])]
    order = [np.array([0])]
    count = 1

    def add(nodes, attach, r0, r1, level):
        nonlocal count
        n = len(nodes)
        positions.append(nodes)
        parent.append(np.concatenate(([attach], count + np.arange(n - 1))))
        radius.append(np.linspace(r0, r1, n))
        order.append(np.full(n, level))
        ids = count + np.arange(n)
        count += n
        return ids

    trunk = add(_branch(np.zeros(3), np.array([0.05, 0.0, 1.0]), height * 0.85, 12, 0.0, rng),
                0, 0.038 * height, 0.006 * height, 0)
    leaf_nodes = []
    for b in range(n_branches):
        at = trunk[int(rng.integers(3, len(trunk) - 1))]
        phi = b * np.radians(137.5) + rng.uniform(-0.2, 0.2)
        direction = np.array([np.cos(phi), np.sin(phi), rng.uniform(0.3, 0.9)])
        start = np.concatenate(positions)[at]
        r0 = 0.4 * np.concatenate(radius)[at]
        branch = add(_branch(start, direction, height * rng.uniform(0.25, 0.4), nodes_per_branch, 0.2, rng),
                     at, r0, 0.15 * r0, 1)
        for _ in range(n_twigs):
            at2 = branch[int(rng.integers(1, len(branch) - 1))]
            start2 = np.concatenate(positions)[at2]
            direction2 = rng.normal(0, 1, 3) + direction
            twig = add(_branch(start2, direction2, height * rng.uniform(0.08, 0.15), 4, 0.1, rng),
                       at2, 0.4 * r0, 0.2 * r0 * 0.4, 2)
            leaf_nodes.extend(rng.choice(twig, leaves_per_twig))
    positions = np.concatenate(positions).astype(np.float32)
    leaf_node = np.asarray(leaf_nodes, np.int32)
    leaves = _leaf_transforms(positions[leaf_node], 0.03 * height, rng)
    return Skeleton(positions, np.concatenate(parent), np.concatenate(radius), np.concatenate(order),
                    leaves, leaf_node)


def _leaf_transforms(anchors: np.ndarray, size: float, rng: np.random.Generator) -> np.ndarray:
    """(M, 4, 4) float32 random leaf placements of about `size` metres at `anchors` (M, 3)."""
    m = len(anchors)
    length_dir = rng.normal(0, 1, (m, 3))
    length_dir /= np.linalg.norm(length_dir, axis=1, keepdims=True)
    helper = np.where(np.abs(length_dir[:, 2:3]) < 0.9, [[0, 0, 1.0]], [[1.0, 0, 0]])
    width_dir = np.cross(helper, length_dir)
    width_dir /= np.linalg.norm(width_dir, axis=1, keepdims=True)
    normal = np.cross(length_dir, width_dir)
    T = np.zeros((m, 4, 4))
    T[:, :3, 0] = width_dir * size * 0.6
    T[:, :3, 1] = normal
    T[:, :3, 2] = length_dir * size
    T[:, :3, 3] = anchors
    T[:, 3, 3] = 1
    return T.astype(np.float32)


def tube_mesh(skeleton: Skeleton, sides: int = 8, radius_scale: float = 1.0) -> MeshPart:
    """Bark: one open tapered tube per skeleton edge, `sides` around, with `order` and `branch` attributes."""
    child = np.arange(1, len(skeleton))
    a = skeleton.positions[skeleton.parent[child]].astype(np.float64)
    b = skeleton.positions[child].astype(np.float64)
    axis = b - a
    axis /= np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-9)
    helper = np.where(np.abs(axis[:, 2:3]) < 0.9, [[0, 0, 1.0]], [[1.0, 0, 0]])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(axis, u)
    angle = np.arange(sides) * 2 * np.pi / sides
    ring = np.cos(angle)[None, :, None] * u[:, None] + np.sin(angle)[None, :, None] * v[:, None]  # (S, k, 3)
    r_a = skeleton.radius[skeleton.parent[child]][:, None, None] * radius_scale
    r_b = skeleton.radius[child][:, None, None] * radius_scale
    verts = np.stack([a[:, None] + r_a * ring, b[:, None] + r_b * ring], axis=1)  # (S, 2, k, 3)
    normals = np.broadcast_to(ring[:, None], verts.shape)
    s = len(child)
    base = (np.arange(s) * 2 * sides)[:, None]
    k0 = np.arange(sides)[None]
    k1 = (k0 + 1) % sides
    lo0, lo1, hi0, hi1 = base + k0, base + k1, base + sides + k0, base + sides + k1
    faces = np.concatenate([np.stack([lo0, lo1, hi1], -1), np.stack([lo0, hi1, hi0], -1)], axis=1)
    per_vertex = lambda arr: np.repeat(arr, 2 * sides)  # noqa: E731
    uvs = np.zeros((s * 2 * sides, 2))
    return MeshPart(verts.reshape(-1, 3), faces.reshape(-1, 3), normals.reshape(-1, 3), uvs,
                    {"order": per_vertex(skeleton.order[child]).astype(np.uint8),
                     "branch": per_vertex(skeleton.branch_id[child]).astype(np.int32)})


def leaf_mesh(skeleton: Skeleton) -> MeshPart:
    """Leaves: one quad (two triangles) per leaf card, with the `node` attribute."""
    corners = skeleton.leaf_corners().reshape(-1, 3)
    m = skeleton.n_leaves
    base = (np.arange(m) * 4)[:, None]
    faces = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    normal = np.repeat(skeleton.leaves[:, :3, 1], 4, axis=0)
    normal = normal / np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-9)
    uvs = np.tile([[0, 0], [1, 0], [1, 1], [0, 1]], (m, 1))
    return MeshPart(corners, faces, normal, uvs, {"node": np.repeat(skeleton.leaf_node, 4).astype(np.int32)})


def make_tree(rng: np.random.Generator, sides: int = 8, **skeleton_kwargs) -> tuple[TreeMesh, Skeleton]:
    """A small test tree: (TreeMesh, Skeleton) that match each other."""
    skeleton = make_skeleton(rng, **skeleton_kwargs)
    return TreeMesh(tube_mesh(skeleton, sides), leaf_mesh(skeleton), name="test_tree"), skeleton
