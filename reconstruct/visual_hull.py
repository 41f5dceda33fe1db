"""A tree's volume from its outlines (issue 51): voxel carving of tree masks seen from registered cameras.

In: one (H, W) bool mask per photo and its `PinholeView` (a world-to-camera rotation, a centre and pinhole
intrinsics in the frame the hull is carved in), a box to carve and a voxel size. Out: a `VisualHull`, the voxels
that enough of the cameras seeing them see inside the tree's mask; its `space()` is a `VoxelSpace` for growth.

Carving is conservative: a voxel stays in a view when its projected ball (half its diagonal) reaches the mask,
so a hull carved from exact masks holds the whole shape and is at most about a voxel larger than the cameras'
outlines allow. Wrong masks (a branch lost to the sky filter, a photo where a person walks past) carve too much;
a voxel therefore stays when at least `agree` of the cameras that see it keep it, not all of them. Points known
to lie on the tree (SfM's) keep the voxels they fall in where at least half of the cameras seeing them agree.

Every voxel centre is projected into one camera at a time, all at once (numpy); nothing loops over voxels.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import ndimage

from renderers.camera import Camera
from species.colonization import VoxelSpace

from .photo_folder import PhotoError

__all__ = ["PinholeView", "VisualHull", "HullError", "carve", "free_votes", "DEFAULT_AGREE", "MAX_VOXELS"]

DEFAULT_AGREE = 0.8       # the share of the cameras seeing a voxel that must keep it
POINT_AGREE = 0.5         # the share of the cameras seeing a voxel that must keep it for a point in it to count
FREE_VOTES = 3            # sightlines crossing a voxel that carve it
FREE_STOP = 1.5           # voxels: a sightline frees the space up to this far short of the point it saw
SIGHTLINE_CHUNK = 4096    # sightlines traced at once (memory: about 200 samples each)
MAX_VOXELS = 4_000_000    # a grid larger than this is refused (memory: a few float arrays of this length)


class HullError(PhotoError):
    """Masks and cameras that carve no tree: no view, masks all empty, or a hull with no voxel left."""


@dataclass(frozen=True)
class PinholeView:
    """A photo's camera. rotation (3, 3) world-to-camera (OpenCV axes: x right, y down, z forward), centre (3,)
    in the world, focal (fx, fy) and principal point (cx, cy) in pixels where pixel (0, 0) spans [0, 1) x [0, 1)
    (COLMAP's convention), size (width, height) pixels."""

    rotation: np.ndarray
    centre: np.ndarray
    focal: tuple[float, float]
    principal: tuple[float, float]
    size: tuple[int, int]

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, 2) pixel coordinates (u, v) and (N,) depths along the optical axis of world points (N, 3)."""
        local = (points - self.centre) @ self.rotation.T
        depth = local[:, 2]
        safe = np.where(depth > 1e-9, depth, 1e-9)
        uv = np.stack([self.focal[0] * local[:, 0] / safe + self.principal[0],
                       self.focal[1] * local[:, 1] / safe + self.principal[1]], axis=1)
        return uv, depth

    @classmethod
    def from_camera(cls, camera: Camera) -> "PinholeView":
        """A perspective `renderers.camera.Camera` (OpenCV pixel centres: its principal point moves half a pixel)."""
        K = np.asarray(camera.K, np.float64)
        return cls(np.asarray(camera.world_to_camera[:3, :3], np.float64), np.asarray(camera.position, np.float64),
                   (float(K[0, 0]), float(K[1, 1])), (float(K[0, 2]) + 0.5, float(K[1, 2]) + 0.5),
                   (int(camera.width), int(camera.height)))

    def to_camera(self, name: str = "view", near: float = 0.1, far: float = 1000.0) -> Camera:
        """The perspective `renderers.camera.Camera` this view is (`from_camera`'s inverse)."""
        world_to_camera = np.eye(4)
        world_to_camera[:3, :3] = self.rotation
        world_to_camera[:3, 3] = -self.rotation @ self.centre
        K = np.array([[self.focal[0], 0.0, self.principal[0] - 0.5], [0.0, self.focal[1], self.principal[1] - 0.5],
                      [0.0, 0.0, 1.0]])
        return Camera(int(self.size[0]), int(self.size[1]), K, world_to_camera, "perspective", near, far, name=name)


@dataclass(frozen=True, eq=False)
class VisualHull:
    """occupancy (X, Y, Z) bool, voxel (i, j, k) spanning origin + [i, i + 1) * voxel_size; seen (X, Y, Z) int,
    the cameras that see each voxel's centre; kept (X, Y, Z) int, those whose mask keeps it."""

    occupancy: np.ndarray
    origin: np.ndarray
    voxel_size: float
    seen: np.ndarray
    kept: np.ndarray

    def centres(self) -> np.ndarray:
        """(K, 3) float64: the centres of the occupied voxels."""
        return self.origin + (np.argwhere(self.occupancy) + 0.5) * self.voxel_size

    def top(self) -> float:
        """The height (z, metres) of the top of the highest occupied voxel."""
        return float(self.centres()[:, 2].max() + 0.5 * self.voxel_size)

    def space(self, shift: np.ndarray | None = None) -> VoxelSpace:
        """The hull as a growth space, moved by `shift` (3,) metres (e.g. into a tree's base frame)."""
        origin = self.origin if shift is None else self.origin + np.asarray(shift, np.float64)
        return VoxelSpace(self.occupancy, origin, self.voxel_size)


def _grid(bounds: np.ndarray, voxel_size: float) -> tuple[np.ndarray, tuple[int, int, int]]:
    lo, hi = np.asarray(bounds, np.float64)
    if not (np.all(np.isfinite(bounds)) and np.all(hi > lo)):
        raise HullError(f"hull bounds {np.round(bounds, 3).tolist()} are empty: allowed lo < hi on every axis")
    if not voxel_size > 0:
        raise HullError(f"voxel size {voxel_size!r} is invalid: allowed > 0 metres")
    shape = tuple(int(n) for n in np.maximum(np.ceil((hi - lo) / voxel_size), 1))
    if int(np.prod(shape)) > MAX_VOXELS:
        raise HullError(f"a {shape} voxel grid is larger than {MAX_VOXELS} voxels: allowed a larger voxel size")
    return lo, shape  # type: ignore[return-value]


def free_votes(shape: tuple[int, int, int], origin: np.ndarray, voxel_size: float, starts: np.ndarray,
               ends: np.ndarray) -> np.ndarray:
    """(X, Y, Z) int32: how many sightlines cross each voxel of the grid (`shape`, `origin`, `voxel_size` as a
    `VisualHull`'s), a sightline running from a camera's centre `starts` (S, 3) to a point that camera saw `ends`
    (S, 3), up to FREE_STOP voxels short of it. Each line is sampled every half voxel and counts once a voxel."""
    size = int(np.prod(shape))
    votes = np.zeros(size, np.int64)
    lo = np.asarray(origin, np.float64)
    hi = lo + np.array(shape) * voxel_size
    step = 0.5 * voxel_size
    for first in range(0, len(starts), SIGHTLINE_CHUNK):
        start = np.asarray(starts[first:first + SIGHTLINE_CHUNK], np.float64)
        line = np.asarray(ends[first:first + SIGHTLINE_CHUNK], np.float64) - start
        length = np.linalg.norm(line, axis=1)
        safe = np.where(np.abs(line) < 1e-12, 1e-12, line)
        near, far = (lo - start) / safe, (hi - start) / safe      # where each line meets the box's slabs
        enter = np.maximum(np.minimum(near, far).max(axis=1), 0.0)
        leave = np.minimum(np.maximum(near, far).min(axis=1), 1.0 - FREE_STOP * voxel_size / np.maximum(length, 1e-9))
        samples = np.where(leave > enter, np.ceil((leave - enter) * length / step), 0).astype(np.int64)
        if not samples.any():
            continue
        which = np.repeat(np.arange(len(start)), samples)
        along = np.arange(int(samples.sum())) - np.repeat(np.cumsum(samples) - samples, samples)
        t = enter[which] + (along + 0.5) * step / length[which]
        ijk = np.floor((start[which] + t[:, None] * line[which] - lo) / voxel_size).astype(np.int64)
        ijk = np.clip(ijk, 0, np.array(shape) - 1)
        crossed = np.unique(which * size + np.ravel_multi_index(tuple(ijk.T), shape))
        votes += np.bincount(crossed % size, minlength=size)
    return votes.reshape(shape).astype(np.int32)


def carve(masks: Sequence[np.ndarray], views: Sequence[PinholeView], bounds: np.ndarray, voxel_size: float, *,
          agree: float = DEFAULT_AGREE, min_views: int = 2, points: np.ndarray | None = None,
          sightlines: tuple[np.ndarray, np.ndarray] | None = None) -> VisualHull:
    """The visual hull of `masks` seen by `views` inside `bounds` ((2, 3) metres, lo and hi), `voxel_size` metres.

    agree     : a voxel stays when at least this share of the views that see its centre keep it (1.0: all).
    min_views : a voxel seen by fewer views is dropped (too little to carve it).
    points    : (P, 3) points on the tree; the voxels they fall in stay when at least POINT_AGREE of the views that
                see them keep them (a point restores what a few wrong masks carved, not what none of them holds).
    sightlines: (starts, ends), each (S, 3): camera centres and points those cameras saw (SfM's tracks); a voxel
                that FREE_VOTES of them cross is empty whatever the masks say (`free_votes`): the ground seen
                under a crown carves the space a wrong mask's shadow, or every raised camera, leaves there.
    Raises HullError when there is no view, the masks are all empty, or nothing is left.
    """
    if not views or len(masks) != len(views):
        raise HullError(f"{len(views)} cameras and {len(masks)} masks: allowed at least one registered photo, "
                        f"one mask each")
    if not 0.0 < agree <= 1.0:
        raise HullError(f"agree {agree!r} is out of range: allowed (0, 1]")
    masks = [np.asarray(m, bool) for m in masks]
    if not any(m.any() for m in masks):
        raise HullError(f"the tree masks of all {len(masks)} photos are empty: no tree was found in the photos")
    origin, shape = _grid(bounds, voxel_size)
    axes = [origin[d] + (np.arange(shape[d]) + 0.5) * voxel_size for d in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    seen = np.zeros(len(centres), np.int32)
    kept = np.zeros(len(centres), np.int32)
    radius = 0.5 * np.sqrt(3.0) * voxel_size
    for mask, view in zip(masks, views):
        height, width = mask.shape
        if (width, height) != tuple(view.size):
            raise HullError(f"a mask of {width} x {height} px for a camera of {view.size[0]} x {view.size[1]} px: "
                            f"allowed one the photo's size")
        # pixels from the mask (0 inside), so a voxel whose projected ball reaches the mask stays
        outside = ndimage.distance_transform_edt(~mask) if mask.any() else np.full(mask.shape, np.inf)
        uv, depth = view.project(centres)
        column, row = np.floor(uv[:, 0]).astype(np.int64), np.floor(uv[:, 1]).astype(np.int64)
        visible = (depth > radius) & (column >= 0) & (column < width) & (row >= 0) & (row < height)
        index = np.flatnonzero(visible)
        reach = radius * max(view.focal) / depth[index] + 0.5
        seen[index] += 1
        kept[index] += outside[row[index], column[index]] <= reach
    occupancy = (seen >= min_views) & (kept >= agree * seen)
    if sightlines is not None and len(sightlines[0]):
        occupancy &= free_votes(shape, origin, voxel_size, *sightlines).ravel() < FREE_VOTES
    if points is not None and len(points):
        ijk = np.floor((np.asarray(points, np.float64) - origin) / voxel_size).astype(np.int64)
        ijk = ijk[np.all((ijk >= 0) & (ijk < np.array(shape)), axis=1)]
        at = np.ravel_multi_index(tuple(ijk.T), shape)
        # a stray point (sky, a leaf's reflection mismatched) over the crown would keep a voxel no mask holds
        backed = (seen[at] > 0) & (kept[at] >= POINT_AGREE * seen[at])
        occupancy[at[backed]] = True
    if not occupancy.any():
        raise HullError(f"no voxel of {len(centres)} is inside the tree's outline in enough photos: the masks "
                        "and cameras do not agree on a tree")
    return VisualHull(occupancy.reshape(shape), origin, float(voxel_size), seen.reshape(shape), kept.reshape(shape))
