"""Skeleton strokes: the main-branch rule, the fixed 12-hue palette, and rasterised colour strokes with their depth.

In: a Skeleton and a Camera; out: trunk strokes (H, W, 3) uint8, trunk depth (H, W) float32, projected branch paths.

Main branches (seed 000's "main trunk", digest 1.8 default): the trunk (the branch holding the root) plus every
branch of order <= 2 that is longer than 10% of the tree height and grows from a main branch (so every stroke
touches the stroke it grows from). Branches are numbered in BFS order over the branch hierarchy: the trunk, then
its main children by where they leave it (from the base up), then theirs, level by level; branch k gets
PALETTE[k % 12]. Strokes are 4 px wide, sampled every pixel along each projected segment and splatted as discs;
where strokes overlap, the one nearer the camera wins, so colours and depth agree at crossings.
"""
from __future__ import annotations

import numpy as np

from species.skeleton import Skeleton

from .camera import Camera

__all__ = ["PALETTE", "main_branches", "branch_polylines", "rasterize_strokes", "trunk_strokes",
           "MAIN_MAX_ORDER", "MAIN_MIN_LENGTH_SHARE", "STROKE_WIDTH_PX"]

MAIN_MAX_ORDER = 2
MAIN_MIN_LENGTH_SHARE = 0.10
STROKE_WIDTH_PX = 4.0


def _palette() -> np.ndarray:
    """(12, 3) uint8 RGB: 12 hues 30 degrees apart, saturated, alternately bright and darker so neighbours differ."""
    hue = np.arange(12) * 30.0
    value = np.where(np.arange(12) % 2 == 0, 1.0, 0.75)
    c = value[:, None] * np.clip(np.abs(((hue[:, None] / 60.0 + [0, 4, 2]) % 6) - 3) - 1, 0, 1)
    return np.round(c * 255).astype(np.uint8)


PALETTE = _palette()
PALETTE.setflags(write=False)


def main_branches(skeleton: Skeleton) -> np.ndarray:
    """(B,) int32 branch ids of the main branches in BFS order (trunk first); see the module docstring."""
    starts = skeleton.branch_starts
    bid = skeleton.branch_id
    length = np.bincount(bid, weights=skeleton.segment_lengths, minlength=len(starts))
    parent_node = skeleton.parent[starts]
    parent_branch = np.where(parent_node >= 0, bid[np.maximum(parent_node, 0)], -1)
    junction_depth = np.where(parent_node >= 0, skeleton.depth[np.maximum(parent_node, 0)], -1)
    trunk = int(bid[0])
    eligible = (skeleton.order[starts] <= MAIN_MAX_ORDER) & (length > MAIN_MIN_LENGTH_SHARE * skeleton.height)
    eligible[trunk] = True
    rank = np.full(len(starts), -1, np.int64)
    rank[trunk] = 0
    level = np.array([trunk])
    next_rank = 1
    while len(level):
        # Children of this level, eligible and not yet ranked, ordered by parent rank then junction height.
        kids = np.flatnonzero(eligible & (rank < 0) & np.isin(parent_branch, level))
        kids = kids[np.lexsort((starts[kids], junction_depth[kids], rank[parent_branch[kids]]))]
        rank[kids] = next_rank + np.arange(len(kids))
        next_rank += len(kids)
        level = kids
    ranked = np.flatnonzero(rank >= 0)
    return ranked[np.argsort(rank[ranked])].astype(np.int32)


def branch_polylines(skeleton: Skeleton, branches: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments of the given branches' paths: start nodes (S,) int32, end nodes (S,) int32, and the position
    (S,) int32 of each segment's branch in `branches`."""
    paths = skeleton.branch_paths
    a, b, k = [], [], []
    for i, branch in enumerate(branches):
        path = paths[int(branch)]
        a.append(path[:-1])
        b.append(path[1:])
        k.append(np.full(len(path) - 1, i, np.int32))
    if not a:
        empty = np.zeros(0, np.int32)
        return empty, empty, empty
    return np.concatenate(a), np.concatenate(b), np.concatenate(k)


def rasterize_strokes(camera: Camera, starts: np.ndarray, ends: np.ndarray, labels: np.ndarray,
                      width_px: float = STROKE_WIDTH_PX) -> tuple[np.ndarray, np.ndarray]:
    """Draw 3D segments as `width_px` wide strokes, nearest wins.

    starts, ends : (S, 3) float metres, world; labels : (S,) int, a value per segment.
    Returns label image (H, W) int64 (-1 where no stroke) and depth (H, W) float32 metres (0 where no stroke).
    """
    h, w = camera.height, camera.width
    label_im = np.full((h, w), -1, np.int64)
    depth_im = np.zeros((h, w), np.float32)
    if len(starts) == 0:
        return label_im, depth_im
    p0, _ = camera.project(starts)
    p1, _ = camera.project(ends)
    n = np.clip(np.ceil(np.linalg.norm(p1 - p0, axis=1)).astype(np.int64), 1, 4 * (h + w)) + 1
    seg = np.repeat(np.arange(len(starts)), n)
    first = np.repeat(np.cumsum(n) - n, n)
    t = ((np.arange(len(seg)) - first) / np.repeat(n - 1, n))[:, None]
    points = starts[seg] * (1 - t) + ends[seg] * t  # sampled in 3D, so depth is exact under perspective
    uv, z = camera.project(points)
    radius = width_px / 2
    r = int(np.ceil(radius))
    off = np.stack(np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing="xy"), -1).reshape(-1, 2)
    centre = np.round(uv).astype(np.int64)
    pix = centre[:, None, :] + off[None]                                  # (P, O, 2) candidate pixel centres
    keep = (((pix - uv[:, None, :]) ** 2).sum(-1) < radius ** 2)
    keep &= (pix[..., 0] >= 0) & (pix[..., 0] < w) & (pix[..., 1] >= 0) & (pix[..., 1] < h)
    keep &= (z > camera.near * 0.5)[:, None]
    sample = np.broadcast_to(np.arange(len(uv))[:, None], keep.shape)[keep]
    flat = pix[keep][:, 1] * w + pix[keep][:, 0]
    zs = z[sample]
    # Nearest wins: sort by (pixel, depth) and take the first entry of each pixel.
    order = np.lexsort((zs, flat))
    flat, sample, zs = flat[order], sample[order], zs[order]
    first_of_pixel = np.ones(len(flat), bool)
    first_of_pixel[1:] = flat[1:] != flat[:-1]
    label_im.ravel()[flat[first_of_pixel]] = np.asarray(labels)[seg[sample[first_of_pixel]]]
    depth_im.ravel()[flat[first_of_pixel]] = zs[first_of_pixel]
    return label_im, depth_im


def trunk_strokes(camera: Camera, skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """Seed 000's trunk pair: colour strokes (H, W, 3) uint8 (white background, branch k in PALETTE[k % 12])
    and trunk depth (H, W) float32 in [0, 1] between the camera's near and far planes (1 = no stroke)."""
    branches = main_branches(skeleton)
    a, b, k = branch_polylines(skeleton, branches)
    pos = skeleton.positions.astype(np.float64)
    labels, depth = rasterize_strokes(camera, pos[a], pos[b], k)
    colours = np.full((camera.height, camera.width, 3), 255, np.uint8)
    drawn = labels >= 0
    colours[drawn] = PALETTE[labels[drawn] % len(PALETTE)]
    return colours, camera.depth01(depth)
