"""Previews of library assets: a shaded thumbnail, an 8-frame turntable strip, per-species contact sheets and a
static `index.html` gallery that opens from disk.

In: a LibraryAsset and the process's depth renderer; out: uint8 RGB images and PNG/HTML bytes.
"""
from __future__ import annotations

import html

import numpy as np

from renderers.camera import perspective_camera
from renderers.maps import combine_parts, normals_from_depth
from species.meshing.textures import linear_to_srgb

__all__ = ["shaded_view", "thumbnail", "turntable", "gallery_html", "THUMBNAIL_PX", "TURNTABLE_FRAMES",
           "TURNTABLE_PX"]

THUMBNAIL_PX = 512
TURNTABLE_FRAMES = 8
TURNTABLE_PX = 128
# Light from the upper front left, in camera axes (x right, y down, z forward), and the ambient share.
_LIGHT = np.array([-0.4, -0.6, -0.7]) / np.linalg.norm([-0.4, -0.6, -0.7])
_AMBIENT = 0.35


def shaded_view(renderer, tree, azimuth_deg: float, size: int, points: np.ndarray | None = None) -> np.ndarray:
    """(size, size, 3) uint8 sRGB: the tree from `azimuth_deg` (10 deg elevation), bark and leaves in their base
    colours under one directional light, on white. `points` (K, 3) metres frame the view (default: every
    vertex; `framing_points(tree)` gives the same camera)."""
    if points is None:
        points = np.concatenate([tree.bark.vertices, tree.leaves.vertices])
    camera = perspective_camera(points, azimuth_deg, 10.0, size)
    renderer.load(tree)
    depth, mask, _ = combine_parts(renderer.part_depths(camera, split_orders=False))
    normals = normals_from_depth(camera, depth).astype(np.float32) / 127.5 - 1.0
    covered = mask > 0  # shade only the tree's pixels: the sRGB curve is the costly step
    light = np.clip(-(normals[covered] @ _LIGHT), 0.0, 1.0) * (1 - _AMBIENT) + _AMBIENT
    albedo = np.where((mask[covered] == 1)[:, None], np.asarray(tree.bark_color, np.float64),
                      np.asarray(tree.leaf_color, np.float64))
    colour = np.full(mask.shape + (3,), 255, np.uint8)
    colour[covered] = np.round(linear_to_srgb(albedo * light[:, None]) * 255).astype(np.uint8)
    return colour


def thumbnail(renderer, tree) -> np.ndarray:
    """(512, 512, 3) uint8: the front three-quarter view."""
    return shaded_view(renderer, tree, 30.0, THUMBNAIL_PX)


def turntable(renderer, tree) -> np.ndarray:
    """(128, 8 x 128, 3) uint8: eight views 45 deg apart, side by side."""
    from .asset import framing_points

    points = framing_points(tree)
    return np.concatenate([shaded_view(renderer, tree, 45.0 * k, TURNTABLE_PX, points)
                           for k in range(TURNTABLE_FRAMES)], axis=1)


def gallery_html(rows: list[dict]) -> str:
    """A self-contained gallery page: one card per asset (thumbnail, turntable, facts, file links), relative
    paths only, so it opens from disk (but for the wind example's link). rows: catalog rows (dicts)."""
    from .wind_viewer import wind_link

    cards = []
    for row in rows:
        files = " ".join(f'<a href="{html.escape(path)}">{html.escape(kind)}</a>'
                         for kind, path in sorted(row["files"].items()))
        if "glb" in row["files"]:  # the page needs the folder served over HTTP (ES modules)
            link = html.escape(wind_link(row["files"]["glb"]))
            files += f' <a href="{link}" title="serve the folder over HTTP">wind</a>'
        lods = " / ".join(f"{n}: {t} tris, IoU {i:.2f}" for n, t, i in
                          zip(row["level_names"], row["triangles"], row["iou_min"]))
        cards.append(
            f'<div class="card"><img src="{html.escape(row["thumbnail"])}" width="256" loading="lazy">'
            f'<img src="{html.escape(row["turntable"])}" width="512" loading="lazy">'
            f'<h3>{html.escape(row["id"])}</h3><p>{html.escape(row["species"])} ({html.escape(row["generator"])}),'
            f' {row["height_m"]:.1f} m tall, crown radius {row["crown_radius_m"]:.1f} m</p>'
            f'<p class="small">{html.escape(lods)}</p><p>{files}</p></div>')
    return ("<!doctype html><html><head><meta charset=\"utf-8\"><title>treefarm asset library</title><style>"
            "body{font-family:sans-serif;margin:1em}.card{display:inline-block;vertical-align:top;width:540px;"
            "margin:6px;padding:6px;border:1px solid #ccc}.small{font-size:80%}</style></head><body>"
            f"<h1>treefarm asset library ({len(rows)} assets)</h1>" + "".join(cards) + "</body></html>\n")
