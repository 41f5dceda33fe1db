"""A reconstruction's report as one PNG: the inputs and intermediate maps, the skeleton, and the result, side by side.

Cells: each named input or map (network inputs, ink 1 on 0, are shown black on white; [0, 1] depth maps as grey),
the skeleton's front (x-z) and side (y-z) projections drawn as lines, and the result rendered from the front and
the side (shaded by its normals). One row, written by `renderers.write_contact_sheet`.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from renderers import PALETTE, ViewRenderer, write_contact_sheet
from renderers.sketch import shaded
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

__all__ = ["write_report", "skeleton_drawing", "cloud_drawing", "palette_legend"]

_CELL = 256


def skeleton_drawing(skeleton: Skeleton, axis: int, size: int = _CELL) -> np.ndarray:
    """(size, size, 3) uint8: the skeleton's segments projected on the plane of `axis` (0 = x, 1 = y) and z,
    one scale for both axes, the trunk dark and higher orders lighter."""
    image = np.full((size, size, 3), 255, np.uint8)
    child = np.flatnonzero(skeleton.parent >= 0)
    if skeleton.n_nodes < 2 or child.size == 0:
        return image
    uv = skeleton.positions[:, [axis, 2]].astype(np.float64)
    low, high = uv.min(axis=0), uv.max(axis=0)
    scale = 0.9 * size / max(float((high - low).max()), 1e-9)
    centre = (low + high) / 2
    px = np.column_stack([size / 2 + (uv[:, 0] - centre[0]) * scale, size / 2 - (uv[:, 1] - centre[1]) * scale])
    a, b = np.rint(px[skeleton.parent[child]]).astype(np.int32), np.rint(px[child]).astype(np.int32)
    shade = np.minimum(60 * skeleton.order[child].astype(np.int32), 200)
    for level in np.unique(shade):  # one polyline call per order
        pick = shade == level
        lines = np.stack([a[pick], b[pick]], axis=1)
        cv2.polylines(image, list(lines), False, (int(level),) * 3, 1, cv2.LINE_AA)
    return image


def _shown(name: str, image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    if image.ndim == 3 and image.shape[0] in (1, 3) and image.shape[2] not in (3, 4):  # (C, H, W) network input
        image = np.moveaxis(image, 0, 2)
    if image.ndim == 3 and image.shape[2] == 1:
        image = image[..., 0]
    if image.ndim == 3 and image.shape[2] == 4:
        image = image[..., :3]
    if name == "input" and image.dtype != np.uint8:
        image = 1.0 - np.clip(image, 0.0, 1.0)  # ink 1 on 0 -> black on white
    return image


def write_report(path: str | Path, panels: Sequence[tuple[str, np.ndarray]], skeleton: Skeleton, mesh: TreeMesh,
                 title: str = "reconstruction") -> Path:
    """Write the report PNG: `panels` (name, image), the skeleton's projections, the result's front and side."""
    cells = [(name, _shown(name, image)) for name, image in panels]
    cells += [("skeleton front", skeleton_drawing(skeleton, 0)), ("skeleton side", skeleton_drawing(skeleton, 1))]
    if mesh.n_faces:
        renderer = ViewRenderer(_CELL)
        try:
            views = renderer.render(mesh, skeleton, "two-view", ["normals", "mask"], np.random.default_rng(0))
        finally:
            renderer.close()
        cells += [(f"result {view.name}", shaded(view.images["normals"], view.images["mask"])) for view in views]
    return write_contact_sheet(path, [(title, cells)], cell=_CELL)


def palette_legend(swatch: int = 48) -> np.ndarray:
    """(H, W, 3) uint8 legend of the trunk-stroke palette: the 12 colours in branch order (1 = the trunk, then the
    main branches breadth-first; the 13th branch takes colour 1 again), each with its number and RGB value."""

    rows = []
    for k, colour in enumerate(PALETTE):
        row = np.full((swatch, swatch * 6, 3), 255, np.uint8)
        row[4:-4, 4:swatch - 4] = colour
        label = f"{k + 1:2d}  #{colour[0]:02x}{colour[1]:02x}{colour[2]:02x}" + ("  trunk" if k == 0 else "")
        cv2.putText(row, label, (swatch + 6, swatch // 2 + 6), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1,
                    cv2.LINE_AA)
        rows.append(row)
    return np.concatenate(rows)


def cloud_drawing(points: np.ndarray, axis: int, size: int = _CELL) -> np.ndarray:
    """(size, size, 3) uint8: a point cloud projected on the plane of `axis` (0 = x, 1 = y) and z, one grey dot
    per point, framed as `skeleton_drawing` frames a skeleton of the same extent."""
    image = np.full((size, size, 3), 255, np.uint8)
    if len(points) == 0:
        return image
    uv = np.asarray(points, np.float64)[:, [axis, 2]]
    low, high = uv.min(axis=0), uv.max(axis=0)
    scale = 0.9 * size / max(float((high - low).max()), 1e-9)
    centre = (low + high) / 2
    px = np.rint(np.column_stack([size / 2 + (uv[:, 0] - centre[0]) * scale,
                                  size / 2 - (uv[:, 1] - centre[1]) * scale])).astype(np.int64)
    px = np.clip(px, 0, size - 1)
    image[px[:, 1], px[:, 0]] = (110, 110, 110)
    return image
