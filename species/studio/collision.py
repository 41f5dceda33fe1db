"""Collision capsules along the trunk and first-order branches, and an optional low-poly mesh of them.

In: a Skeleton. Out: capsules (K, 7) float32 (p0 xyz, p1 xyz, radius; metres, Z up) and a MeshPart of them.
"""
from __future__ import annotations

import numpy as np

from ..skeleton import Skeleton
from ..tree_mesh import MeshPart

__all__ = ["collision_capsules", "capsule_mesh", "TRUNK_CAPSULES", "BRANCH_CAPSULES", "MAX_BRANCHES"]

TRUNK_CAPSULES = 4   # the trunk in up to this many pieces
BRANCH_CAPSULES = 1  # each first-order branch in this many
MAX_BRANCHES = 24    # the thickest first-order branches only (physics budgets are small)


def _pieces(path_points: np.ndarray, path_radius: np.ndarray, pieces: int) -> list[list[float]]:
    cut = np.unique(np.linspace(0, len(path_points) - 1, pieces + 1).round().astype(int))
    out = []
    for a, b in zip(cut[:-1], cut[1:]):
        out.append([*path_points[a], *path_points[b], float(path_radius[a:b + 1].max())])
    return out


def collision_capsules(skeleton: Skeleton) -> np.ndarray:
    """(K, 7) float32: capsules (p0, p1, radius) along the trunk and the MAX_BRANCHES thickest first-order
    branches, each piece as thick as its thickest node (so the bark lies inside)."""
    paths = skeleton.branch_paths
    order = skeleton.order[skeleton.branch_starts]
    capsules = []
    for b in np.flatnonzero(order == 0):
        path = paths[b]
        if len(path) >= 2:
            capsules += _pieces(skeleton.positions[path], skeleton.radius[path], TRUNK_CAPSULES)
    first = np.flatnonzero(order == 1)
    thickest = first[np.argsort(-skeleton.radius[skeleton.branch_starts[first]], kind="stable")][:MAX_BRANCHES]
    for b in np.sort(thickest):
        path = paths[b][1:]  # from its own first node: the junction lies inside the trunk's capsule
        if len(path) >= 2:
            capsules += _pieces(skeleton.positions[path], skeleton.radius[path], BRANCH_CAPSULES)
    return np.asarray(capsules, np.float32).reshape(-1, 7)


def capsule_mesh(capsules: np.ndarray, sides: int = 6) -> MeshPart:
    """A low-poly mesh of the capsules (each a closed `sides`-sided capsule with rounded caps), normals outward."""
    import trimesh

    meshes = []
    for p0, p1, radius in zip(capsules[:, :3], capsules[:, 3:6], capsules[:, 6]):
        height = float(np.linalg.norm(p1 - p0))
        capsule = trimesh.creation.capsule(height=max(height, 1e-4), radius=float(radius), count=[sides, sides])
        axis = (p1 - p0) / max(height, 1e-9)
        transform = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], axis)
        transform[:3, 3] = 0.5 * (p0 + p1)
        capsule.apply_transform(transform)
        meshes.append(capsule)
    if not meshes:
        return MeshPart.empty()
    merged = trimesh.util.concatenate(meshes)
    return MeshPart(merged.vertices, merged.faces, merged.vertex_normals, np.zeros((len(merged.vertices), 2)))
