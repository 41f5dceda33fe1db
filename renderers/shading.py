"""Base-colour shading of a tree seen through a camera: one directional light and an ambient share (Lambert) in
linear light, turned to sRGB; what the asset library's thumbnails and turntables are drawn with.

In: a DepthRenderer, a TreeMesh (its bark and leaf base colours), an azimuth and a size; out: uint8 sRGB images.
"""
from __future__ import annotations

import numpy as np

from species.meshing.textures import linear_to_srgb

from .camera import perspective_camera
from .maps import combine_parts, normals_from_depth

__all__ = ["LIGHT_DIRECTION", "AMBIENT", "ELEVATION_DEG", "lambert_srgb", "shaded_view"]

# Light from the upper front left, in camera axes (x right, y down, z forward): unit vector it travels along.
LIGHT_DIRECTION = np.array([-0.4, -0.6, -0.7]) / np.linalg.norm([-0.4, -0.6, -0.7])
# Share of the base colour every pixel gets whatever its normal, so faces turned from the light stay readable.
AMBIENT = 0.35
ELEVATION_DEG = 10.0  # a little above the base, as a tree is usually seen


def lambert_srgb(normals: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """(K, 3) uint8 sRGB of K pixels: `albedo` (K, 3) linear base colours in [0, 1] lit by LIGHT_DIRECTION
    through their `normals` (K, 3) unit vectors in camera axes, plus AMBIENT."""
    light = np.clip(-(normals @ LIGHT_DIRECTION), 0.0, 1.0) * (1 - AMBIENT) + AMBIENT
    return np.round(linear_to_srgb(albedo * light[:, None]) * 255).astype(np.uint8)


def shaded_view(renderer, tree, azimuth_deg: float, size: int, points: np.ndarray | None = None) -> np.ndarray:
    """(size, size, 3) uint8 sRGB: the tree from `azimuth_deg` (ELEVATION_DEG up), bark and leaves in their base
    colours under `lambert_srgb`'s light, on white. `renderer` is a `gl_depth.DepthRenderer`; `points` (K, 3) metres
    frame the view (default: every vertex; `framing.framing_points(tree)` gives the same camera)."""
    if points is None:
        points = np.concatenate([tree.bark.vertices, tree.leaves.vertices])
    camera = perspective_camera(points, azimuth_deg, ELEVATION_DEG, size)
    renderer.load(tree)
    depth, mask, _ = combine_parts(renderer.part_depths(camera, split_orders=False))
    normals = normals_from_depth(camera, depth).astype(np.float32) / 127.5 - 1.0
    covered = mask > 0  # shade only the tree's pixels: the sRGB curve is the costly step
    albedo = np.where((mask[covered] == 1)[:, None], np.asarray(tree.bark_color, np.float64),
                      np.asarray(tree.leaf_color, np.float64))
    colour = np.full(mask.shape + (3,), 255, np.uint8)
    colour[covered] = lambert_srgb(normals[covered], albedo)
    return colour
