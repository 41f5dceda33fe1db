"""Collision capsules along the trunk and first-order branches, and an optional low-poly mesh of them.

In: a Skeleton. Out: capsules (K, 7) float32 (p0 xyz, p1 xyz, radius; metres, Z up) and a MeshPart of them.
"""
from __future__ import annotations

import functools

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
    """A low-poly mesh of the capsules (each a closed `sides`-sided capsule with rounded caps), normals outward.
    Every capsule is one template (trimesh's capsule of unit radius and height) scaled, stretched along its axis,
    turned and placed: the same mesh as a capsule made for each, without building trimesh's capsule each time."""
    import trimesh

    capsules = np.asarray(capsules)
    if len(capsules) == 0:
        return MeshPart.empty()
    template, template_faces, template_normals = _unit_capsule(sides)
    p0, p1, radius = capsules[:, :3], capsules[:, 3:6], capsules[:, 6].astype(np.float64)
    length = np.linalg.norm(p1 - p0, axis=1).astype(np.float64)
    height = np.maximum(length, 1e-4)
    axis = (p1 - p0) / np.maximum(length, 1e-9)[:, None]
    # The template's two hemispheres sit half its unit height either side of its middle: each keeps its side.
    side = np.sign(template[:, 2])
    local = template[None] * radius[:, None, None]
    local[..., 2] = (template[None, :, 2] - 0.5 * side) * radius[:, None] + 0.5 * side * height[:, None]
    turn = np.stack([trimesh.geometry.align_vectors([0.0, 0.0, 1.0], a)[:3, :3] for a in axis])
    centre = (0.5 * (p0 + p1)).astype(np.float64)
    vertices = np.einsum("kij,kvj->kvi", turn, local) + centre[:, None, :]
    normals = np.einsum("kij,vj->kvi", turn, template_normals)
    faces = template_faces[None] + (np.arange(len(capsules)) * len(template))[:, None, None]
    return MeshPart(vertices.reshape(-1, 3), faces.reshape(-1, 3), normals.reshape(-1, 3),
                    np.zeros((len(capsules) * len(template), 2)))


@functools.cache
def _unit_capsule(sides: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """trimesh's capsule of radius 1 and height 1 along z, centred: vertices, faces and vertex normals."""
    import trimesh

    capsule = trimesh.creation.capsule(height=1.0, radius=1.0, count=[sides, sides])
    return (np.asarray(capsule.vertices, np.float64), np.asarray(capsule.faces, np.int64),
            np.asarray(capsule.vertex_normals, np.float64))
