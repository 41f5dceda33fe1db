"""Contact sheets: one grid PNG of trees (rows) x images (columns) with labels, for looking at a batch at a glance.

In: rows of labelled images (uint8 grey or RGB, float maps in [0, 1]); out: a PNG file (`species.meshing.png`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from species.meshing.png import png_bytes

from .views import LABEL_MAPS, METRIC_MAPS, OUTPUTS

__all__ = ["to_rgb8", "viewable", "without_background", "contact_sheet", "write_contact_sheet", "views_sheet_rows"]

LABEL_PX = 18
# Sheets are looked at, not archived: a fast zlib level.
_PNG_COMPRESS_LEVEL = 2


def to_rgb8(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 from a grey or RGB image: uint8 kept, floats taken as [0, 1] (depth, silhouette)."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = np.clip(np.nan_to_num(img.astype(np.float32)) * 255.0, 0, 255).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"a contact sheet cell must be (H, W) or (H, W, 3); got shape {img.shape}")
    return img


def without_background(name: str, image: np.ndarray) -> np.ndarray:
    """A renderer output with 0 (black) outside its foreground mask, for an output that carries one
    (`Output.mask_channel`: the silhouette maps, whose background is otherwise far depth, a red picture); any
    other output as it is."""
    img = np.asarray(image)
    output = OUTPUTS.get(name)
    if output is None or output.mask_channel is None or img.ndim != 3:
        return img
    return np.where(img[..., output.mask_channel:output.mask_channel + 1] > 0, img, 0).astype(img.dtype)


def viewable(name: str, image: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 picture of a renderer output by its name: metric depth scaled to its own range (near
    bright, background black), label maps (mask, order) spread over grey levels, maps with a mask channel black
    outside the tree, the rest as `to_rgb8`."""
    img = without_background(name, image)
    if name in METRIC_MAPS:
        hit = img > 0
        if hit.any():
            lo, hi = float(img[hit].min()), float(img[hit].max())
            grey = np.where(hit, 1.0 - 0.8 * (img - lo) / max(hi - lo, 1e-9), 0.0)
        else:
            grey = np.zeros(img.shape, np.float32)
        return to_rgb8(grey.astype(np.float32))
    if name in LABEL_MAPS:
        return to_rgb8((np.minimum(img.astype(np.int32) * 80, 255)).astype(np.uint8))
    return to_rgb8(img)


def views_sheet_rows(views, prefix: str = "") -> list:
    """Contact sheet rows for a list of RenderedView: one row per view, one column per output."""
    return [(f"{prefix}{view.name}", [(name, viewable(name, image)) for name, image in view.images.items()])
            for view in views]


_FONT, _FONT_SCALE = cv2.FONT_HERSHEY_SIMPLEX, 0.4


def _label(lines: Sequence[str], width: int) -> np.ndarray:
    """(LABEL_PX * len(lines), width, 3) white bar, one line of text each, each shrunk to fit whole: a cut label
    ("trunk_s") hides which output a column is."""
    bar = np.full((LABEL_PX * len(lines), width, 3), 255, np.uint8)
    for k, text in enumerate(lines):
        text_width = cv2.getTextSize(text, _FONT, _FONT_SCALE, 1)[0][0]
        scale = _FONT_SCALE * min(1.0, (width - 6) / max(text_width, 1))
        cv2.putText(bar, text, (3, LABEL_PX * (k + 1) - 5), _FONT, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return bar


def contact_sheet(rows: Sequence[tuple[str, Sequence[tuple[str, np.ndarray]]]], cell: int = 160) -> np.ndarray:
    """(H, W, 3) uint8 grid: each row is (row label, [(column label, image), ...]); cells resized to `cell` px,
    each under two label lines (row, column)."""
    if not rows:
        raise ValueError("a contact sheet needs at least one row")
    n_cols = max(len(cells) for _, cells in rows)
    pad = 4
    row_images = []
    for row_label, cells in rows:
        tiles = []
        for col_label, image in cells:
            tile = cv2.resize(to_rgb8(image), (cell, cell), interpolation=cv2.INTER_AREA)
            tiles.append(np.concatenate([_label([str(row_label), str(col_label)], cell), tile]))
        tiles += [np.full((cell + 2 * LABEL_PX, cell, 3), 255, np.uint8)] * (n_cols - len(tiles))
        spaced = []
        for tile in tiles:
            spaced += [tile, np.full((tile.shape[0], pad, 3), 200, np.uint8)]
        row_images += [np.concatenate(spaced, axis=1), np.full((pad, n_cols * (cell + pad), 3), 200, np.uint8)]
    return np.concatenate(row_images)


def write_contact_sheet(path: str | Path, rows: Sequence[tuple[str, Sequence[tuple[str, np.ndarray]]]],
                        cell: int = 160) -> Path:
    """Write `contact_sheet(rows, cell)` as a PNG at `path` (folders created); returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png_bytes(contact_sheet(rows, cell), _PNG_COMPRESS_LEVEL))
    return path
