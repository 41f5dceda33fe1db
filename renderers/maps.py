"""Per-pixel maps as arrays, from the depths of a tree's parts: depth, masks, branch order, normals, silhouettes.

In: per-part metric depths of one view (`PartDepths`, as `renderers.gl_depth.DepthRenderer` draws them) and its
`Camera`; out: (H, W) arrays (see each function): the visible depth, part mask and order ids (`combine_parts`),
camera-frame and tangent-space normals, albedo by part, the silhouette (front depth, gap, mask) and the crown
envelope, and closed masks. `tree_parts` names the parts a renderer draws a tree in, as `combine_parts` reads them.
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from species.meshing.textures import linear_to_srgb
from species.tree_mesh import TreeMesh

from .camera import Camera

__all__ = ["PartDepths", "combine_parts", "normals_from_depth", "tangent_space_normals", "mask_albedo",
           "silhouette_map", "envelope_silhouette_map", "closed_mask", "LEAVES", "tree_parts",
           "ENVELOPE_CLOSING_256", "ENVELOPE_SIGMA_256"]

LEAVES = "leaves"
# The crown envelope (`envelope_silhouette_map`), in pixels at 256 px, scaled with the image: gaps between leaves
# up to ~8 px are closed (the outline a person draws round a sparse crown), and the depth surfaces are the
# visible surfaces averaged over a Gaussian of sigma 8 px. At 4 px the target still holds the per-leaf depth that
# an edge sketch does not show (a blur oracle of the per-leaf front depth at 4 px scores 0.107, docs/training.md).
ENVELOPE_CLOSING_256 = 4
ENVELOPE_SIGMA_256 = 8.0


def _bark_part(order: int) -> str:
    return f"bark{order}"


@dataclass
class PartDepths:
    """Depth of each part of the tree drawn alone, for one camera.

    depths : part name ("bark0", "bark1", ..., "leaves", or "bark" when bark orders are not split)
             -> (H, W) float32 metres, 0 where the part does not cover the pixel.
    """

    depths: dict[str, np.ndarray]

    @property
    def bark(self) -> np.ndarray:
        """(H, W) float32 metres, nearest bark surface (all orders), 0 where none."""
        parts = [d for name, d in self.depths.items() if name.startswith("bark")]
        return _nearest(parts)[0] if parts else np.zeros_like(self.depths[LEAVES])

    @property
    def leaves(self) -> np.ndarray:
        """(H, W) float32 metres, nearest leaf surface, 0 where none."""
        return self.depths[LEAVES]


def _nearest(depths: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Nearest of several depth maps (0 = empty): (depth (H, W) float32, index (H, W) int64 of the winner, -1).
    On a tie the first map wins. A running minimum map by map: `argmin` over their (K, H, W) stack gives the same
    winners at several times the cost."""
    nearest = np.where(depths[0] > 0, depths[0], np.inf)
    winner = np.zeros(nearest.shape, np.int64)
    for index, depth in enumerate(depths[1:], 1):
        keyed = np.where(depth > 0, depth, np.inf)
        winner = np.where(keyed < nearest, index, winner)
        nearest = np.minimum(nearest, keyed)
    empty = np.isinf(nearest)
    return np.where(empty, 0.0, nearest).astype(np.float32), np.where(empty, -1, winner)


def combine_parts(parts: PartDepths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Visible depth, mask and order from per-part depths.

    Returns depth (H, W) float32 metres (0 background), mask (H, W) uint8 (0 background, 1 bark, 2 leaves) and
    order (H, W) uint8 (branch order + 1 on visible bark; 0 on background and leaves; bark parts named "bark"
    without an order count as order 0).
    """
    names = list(parts.depths)
    depth, winner = _nearest([parts.depths[n] for n in names])
    # Lookup tables by winner index; the extra last entry serves winner -1 (background).
    is_leaf = np.array([n == LEAVES for n in names] + [False])
    order_of = np.array([0 if n == LEAVES else 1 if n == "bark" else int(n[4:]) + 1 for n in names] + [0],
                        np.uint8)
    mask = np.where(winner < 0, 0, np.where(is_leaf[winner], 2, 1)).astype(np.uint8)
    return depth, mask, order_of[winner]


def normals_from_depth(camera: Camera, depth: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 surface normals from a depth map, in camera axes (x right, y down, z forward) mapped from
    [-1, 1] to [0, 255], facing the camera; background (depth 0) is 0."""
    fx, fy = camera.K[0, 0], camera.K[1, 1]
    cx, cy = camera.K[0, 2], camera.K[1, 2]
    z = depth.astype(np.float32)
    u = ((np.arange(z.shape[1], dtype=np.float32) - cx) / fx)[None, :]
    v = ((np.arange(z.shape[0], dtype=np.float32) - cy) / fy)[:, None]
    if camera.is_orthographic:
        x, y = np.broadcast_to(u, z.shape), np.broadcast_to(v, z.shape)
    else:
        x, y = u * z, v * z
    # Per-component gradients, cross product, normalisation and flip: no (H, W, 3) float stacks (each of those
    # steps on a stack, and numpy's reduction along its short last axis, cost more than the arithmetic).
    xu, yu, zu = (_unit_gradient(c, 1) for c in (x, y, z))
    xv, yv, zv = (_unit_gradient(c, 0) for c in (x, y, z))
    nx, ny, nz = yu * zv - zu * yv, zu * xv - xu * zv, xu * yv - yu * xv
    length = np.maximum(np.sqrt(nx * nx + ny * ny + nz * nz), 1e-12)
    nx, ny, nz = nx / length, ny / length, nz / length
    towards = nz if camera.is_orthographic else nx * x + ny * y + nz * z
    away = towards > 0
    background = z <= 0
    out = np.empty(z.shape + (3,), np.uint8)
    for k, component in enumerate((nx, ny, nz)):
        texel = np.clip((np.where(away, -component, component) + 1.0) * 127.5, 0, 255).astype(np.uint8)
        texel[background] = 0
        out[..., k] = texel
    return out


def _unit_gradient(values: np.ndarray, axis: int) -> np.ndarray:
    """`np.gradient(values, axis=axis)` of a 2-D array (unit spacing, first-order edges; the same values: central
    differences halved, one-sided ones at the ends), without its generic set-up."""
    f = np.moveaxis(np.asarray(values), axis, 0)
    out = np.empty(f.shape, np.result_type(f, np.float32))
    out[1:-1] = (f[2:] - f[:-2]) / 2.0
    out[0] = f[1] - f[0]
    out[-1] = f[-1] - f[-2]
    return np.moveaxis(out, 0, axis)


def mask_albedo(mask: np.ndarray, bark_color, leaf_color) -> np.ndarray:
    """(H, W, 4) uint8 sRGB + alpha of a part mask (`combine_parts`: 1 bark, 2 leaves): bark texels in
    `bark_color`, leaf texels in `leaf_color` (linear RGB in [0, 1]) with alpha 255, the rest transparent; leaf
    texels too when `leaf_color` is None."""
    palette = np.zeros((256, 4), np.uint8)  # by mask value: a lookup, not a masked write per part
    for part, colour in ((1, bark_color), (2, leaf_color)):
        if colour is not None:
            palette[part] = (*np.round(linear_to_srgb(np.asarray(colour)) * 255).astype(np.uint8), 255)
    mask = np.asarray(mask, np.uint8)
    image = np.empty(mask.shape + (4,), np.uint8)
    # Each texel's four bytes gathered as one 32-bit word: several times faster than gathering rows of four.
    np.take(palette.view(np.uint32)[:, 0], mask, out=image.view(np.uint32)[..., 0])
    return image


def tangent_space_normals(camera: Camera, depth: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 normal-map texels of an image drawn as a texture seen head-on (x along the image's u,
    y up the image, z toward the viewer, [-1, 1] mapped to [0, 255]) from a depth map; flat (128, 128, 255) where
    not `covered` (H, W) bool."""
    camera_normals = normals_from_depth(camera, depth)
    texels = np.empty(camera_normals.shape, np.uint8)
    for k, (sign, flat) in enumerate(((1.0, 128), (-1.0, 128), (-1.0, 255))):  # camera y down, z forward
        tangent = sign * (camera_normals[..., k].astype(np.float32) / 127.5 - 1.0)
        texels[..., k] = np.clip(np.where(covered, np.round((tangent + 1.0) * 127.5), flat), 0, 255)
    return texels


def silhouette_map(camera: Camera, front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1]: R front depth01 (1 background), G front-to-back gap in depth01 units,
    B foreground mask; from front and back metric depth (H, W) float32 metres of the same camera."""
    mask = front > 0
    f01 = camera.depth01(front)
    b01 = camera.depth01(np.where(mask, back, 0.0))
    gap = np.where(mask, np.clip(b01 - f01, 0.0, 1.0), 0.0)
    return np.stack([f01, gap, mask.astype(np.float32)], axis=-1).astype(np.float32)


def closed_mask(mask: np.ndarray, radius_px: int) -> np.ndarray:
    """(H, W) bool: a mask with gaps narrower than about 2 radius_px pixels closed (dilate, then erode, with a
    (2r+1)-pixel ellipse), padded so the closing is not clipped at the image border."""
    if radius_px <= 0:
        return np.asarray(mask, bool)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_px + 1, 2 * radius_px + 1))
    pad = radius_px + 1
    padded = np.pad(np.asarray(mask, np.uint8), pad)
    return cv2.morphologyEx(padded, cv2.MORPH_CLOSE, kernel)[pad:-pad, pad:-pad] > 0


def _smooth_within(values: np.ndarray, weight: np.ndarray, region: np.ndarray, sigma: float) -> np.ndarray:
    """(H, W) float64: the Gaussian average of `values` over the pixels where weight > 0 (normalised
    convolution), at every pixel of `region`; pixels of the region too far from any weight (a filled hole wider
    than a few sigma) take the average at 4 sigma, then the overall mean."""
    out = np.full(values.shape, float(values[weight > 0].mean()), np.float64)
    todo = region.copy()
    w = weight.astype(np.float64)
    for s in (sigma, 4.0 * sigma):
        num = cv2.GaussianBlur(values * w, (0, 0), s, borderType=cv2.BORDER_CONSTANT)
        den = cv2.GaussianBlur(w, (0, 0), s, borderType=cv2.BORDER_CONSTANT)
        reached = todo & (den > 1e-3)
        out[reached] = num[reached] / den[reached]
        todo &= ~reached
    return out


def envelope_silhouette_map(camera: Camera, front: np.ndarray, back: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 in [0, 1], the crown envelope in `silhouette_map`'s encoding: R front depth01 (1
    background), G front-to-back gap, B mask; from front and back metric depth (H, W) float32 metres.

    The mask is the tree's silhouette closed (ENVELOPE_CLOSING_256 px at 256 px) with its holes filled: one region
    per crown, as a person outlines it. Front and back are the visible front and back depth01 averaged over a
    Gaussian (ENVELOPE_SIGMA_256 px) within the silhouette and carried into the closed gaps: smooth surfaces
    that an outline sketch determines, where the per-leaf depth of `silhouette` varies from pixel to pixel
    (standard deviation 0.16-0.20 within a crown) with nothing in an edge sketch to show it. The seed 000
    growth fills this span with markers, so it is the map reconstruction needs (reconstruct.from_sketch)."""
    from scipy import ndimage  # scipy where used: importing renderers does not load it

    mask = front > 0
    scale = max(mask.shape) / 256.0
    if not mask.any():
        return silhouette_map(camera, front, back)
    crown = ndimage.binary_fill_holes(closed_mask(mask, max(1, round(ENVELOPE_CLOSING_256 * scale))))
    sigma = ENVELOPE_SIGMA_256 * scale
    f01 = camera.depth01(front).astype(np.float64)
    b01 = camera.depth01(np.where(mask, back, 0.0)).astype(np.float64)
    front_env = np.clip(_smooth_within(f01, mask, crown, sigma), 0.0, 1.0)
    back_env = np.clip(_smooth_within(np.maximum(b01, f01), mask, crown, sigma), 0.0, 1.0)
    gap = np.where(crown, np.maximum(back_env - front_env, 0.0), 0.0)
    return np.stack([np.where(crown, front_env, 1.0), gap, crown.astype(np.float64)], axis=-1).astype(np.float32)


def tree_parts(tree: TreeMesh) -> dict[str, tuple[np.ndarray, np.ndarray, bool]]:
    """The parts a renderer draws a tree in: name -> (vertices, faces, double_sided), the bark one part per
    branch order (its `order` attribute; order 0 without one), then the leaves; empty parts left out."""
    parts = {}
    bark = tree.bark
    if bark.n_faces:
        order = bark.attributes.get("order")
        face_order = np.zeros(bark.n_faces, np.uint8) if order is None else np.asarray(order)[bark.faces[:, 0]]
        for value in np.unique(face_order):
            parts[_bark_part(int(value))] = (bark.vertices, bark.faces[face_order == value], False)
    if tree.leaves.n_faces:
        parts[LEAVES] = (tree.leaves.vertices, tree.leaves.faces, True)
    return parts
