"""Previews of library assets: a shaded thumbnail, an 8-frame turntable strip and a static `index.html` gallery
that opens from disk (the per-species contact sheets are `catalog.write_catalog`'s).

In: a LibraryAsset's LOD0 and the process's depth renderer (drawn by `renderers.shading.shaded_view`), or catalog
rows; out: uint8 RGB images and HTML text.
"""
from __future__ import annotations

import html

import numpy as np

from renderers.framing import framing_points
from renderers.shading import shaded_view

from .wind_viewer import wind_link

__all__ = ["thumbnail", "turntable", "gallery_html", "THUMBNAIL_PX", "THUMBNAIL_AZIMUTH_DEG", "TURNTABLE_FRAMES",
           "TURNTABLE_PX"]

THUMBNAIL_PX = 512
THUMBNAIL_AZIMUTH_DEG = 30.0  # front three-quarter
TURNTABLE_FRAMES = 8
TURNTABLE_PX = 128


def thumbnail(renderer, tree) -> np.ndarray:
    """(512, 512, 3) uint8: the front three-quarter view."""
    return shaded_view(renderer, tree, THUMBNAIL_AZIMUTH_DEG, THUMBNAIL_PX)


def turntable(renderer, tree) -> np.ndarray:
    """(128, 8 x 128, 3) uint8: eight views 45 deg apart, side by side, all framed by the same points."""
    points = framing_points(tree)
    return np.concatenate([shaded_view(renderer, tree, 360.0 / TURNTABLE_FRAMES * k, TURNTABLE_PX, points)
                           for k in range(TURNTABLE_FRAMES)], axis=1)


def gallery_html(rows: list[dict]) -> str:
    """A self-contained gallery page: one card per asset (thumbnail, turntable, facts, file links), relative
    paths only, so it opens from disk (but for the wind example's link). rows: catalog rows (dicts)."""
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
