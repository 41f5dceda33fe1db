"""Synthetic scans of generated trees, the ground truth the cloud tests, benchmarks and evaluation jobs share.

In: a `TreeMesh` (bark, and leaves for clutter) and a numpy Generator. Out: a `SampledCloud`: points on the bark
(area-weighted, with Gaussian range noise), optional leaf clutter on the leaf cards, uniform outliers in the padded
box above the ground, and an occlusion wedge (an azimuth sector seen from the trunk's axis left empty, as a scanner's shadow).
Same mesh, same arguments and same seed: the same bytes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from species.tree_mesh import MeshPart, TreeMesh

from .clouds import CloudError

__all__ = ["SampledCloud", "sample_tree_cloud", "WOOD", "LEAF", "OUTLIER"]

WOOD, LEAF, OUTLIER = 0, 1, 2


@dataclass(frozen=True, eq=False)
class SampledCloud:
    """points : (N, 3) float32 metres, in the mesh's frame; labels : (N,) uint8, WOOD, LEAF or OUTLIER."""

    points: np.ndarray
    labels: np.ndarray


def _surface(part: MeshPart, n: int, rng: np.random.Generator) -> np.ndarray:
    if n == 0 or part.n_faces == 0:
        return np.zeros((0, 3))
    areas = part.face_areas.astype(np.float64)
    face = rng.choice(len(areas), size=n, p=areas / areas.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    corners = part.vertices[part.faces[face]].astype(np.float64)
    return corners[:, 0] + u[:, None] * (corners[:, 1] - corners[:, 0]) + v[:, None] * (corners[:, 2] - corners[:, 0])


def _share(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 <= value < 1:
        raise CloudError(f"{name} = {value!r}: allowed a share in [0, 1)")
    return float(value)


def sample_tree_cloud(mesh: TreeMesh, rng: np.random.Generator, *, n_points: int, leaf_fraction: float = 0.0,
                      outlier_fraction: float = 0.0, occlusion_wedge_deg: float = 0.0,
                      noise_m: float = 0.005) -> SampledCloud:
    """A scan of `mesh` with `n_points` points before the wedge removes its share: (1 - leaf - outlier) of them
    on the bark, `leaf_fraction` on the leaf cards, `outlier_fraction` uniform in the box padded by 10 %. Bark
    and leaf points get Gaussian noise of `noise_m` metres per axis. The wedge, centred on a random azimuth about
    the vertical through the bark's centroid, removes every point in it."""
    if not isinstance(mesh, TreeMesh) or mesh.bark.n_faces == 0:
        raise CloudError("mesh must be a TreeMesh with bark faces")
    if not isinstance(rng, np.random.Generator):
        raise CloudError(f"rng is a {type(rng).__name__}: allowed a numpy.random.Generator")
    if isinstance(n_points, bool) or not isinstance(n_points, (int, np.integer)) or n_points < 1:
        raise CloudError(f"n_points = {n_points!r}: allowed an integer >= 1")
    leaf, outlier = _share(leaf_fraction, "leaf_fraction"), _share(outlier_fraction, "outlier_fraction")
    if leaf + outlier >= 1:
        raise CloudError(f"leaf_fraction + outlier_fraction = {leaf + outlier}: allowed less than 1")
    if leaf > 0 and mesh.leaves.n_faces == 0:
        raise CloudError(f"leaf_fraction = {leaf}: the mesh has no leaves; allowed 0")
    if not (isinstance(occlusion_wedge_deg, (int, float)) and 0 <= occlusion_wedge_deg < 360):
        raise CloudError(f"occlusion_wedge_deg = {occlusion_wedge_deg!r}: allowed degrees in [0, 360)")
    if not (isinstance(noise_m, (int, float)) and 0 <= noise_m < 1):
        raise CloudError(f"noise_m = {noise_m!r}: allowed metres in [0, 1)")
    n_leaf, n_out = int(round(leaf * n_points)), int(round(outlier * n_points))
    n_wood = n_points - n_leaf - n_out
    wood = _surface(mesh.bark, n_wood, rng)
    leaves = _surface(mesh.leaves, n_leaf, rng)
    surface = np.concatenate([wood, leaves])
    surface += rng.normal(0.0, noise_m, surface.shape) if noise_m > 0 else 0.0
    low, high = mesh.bark.vertices.min(axis=0), mesh.bark.vertices.max(axis=0)
    pad = 0.1 * (high - low)
    # Stray returns fill the padded box above the ground (the base plane), not below it.
    outliers = rng.uniform(low - pad * [1, 1, 0], high + pad, (n_out, 3))
    points = np.concatenate([surface, outliers])
    labels = np.repeat(np.array([WOOD, LEAF, OUTLIER], np.uint8), [n_wood, n_leaf, n_out])
    if occlusion_wedge_deg > 0:
        centre = wood.mean(axis=0)
        azimuth = np.degrees(np.arctan2(points[:, 1] - centre[1], points[:, 0] - centre[0]))
        facing = rng.uniform(-180.0, 180.0)
        offset = (azimuth - facing + 180.0) % 360.0 - 180.0
        keep = np.abs(offset) > occlusion_wedge_deg / 2
        points, labels = points[keep], labels[keep]
    return SampledCloud(points.astype(np.float32), labels)
