"""A quick front view (x, z) of a skeleton for the benchmarks' PNGs: branches to scale, leaf centres as dots."""
from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

import species
from species.meshing.png import png_bytes


def front_view(skeleton: species.Skeleton, title: str, size: int = 320, leaves: bool = True) -> Image.Image:
    """An RGB image `size` pixels square: branch widths to scale, leaf centres green, `title` at the top left."""
    image = Image.new("RGB", (size, size), "white")
    draw = ImageDraw.Draw(image)
    xz = skeleton.positions[:, [0, 2]]
    low, span = xz.min(0), max(float(np.ptp(xz, axis=0).max()), 1e-6)
    pixels = (xz - low) / span * (size - 20) + 10
    pixels[:, 1] = size - pixels[:, 1]
    widths = np.maximum(1, (skeleton.radius / span * (size - 20) * 2).astype(int))
    for child, parent in zip(range(1, len(skeleton)), skeleton.parent[1:].tolist()):
        draw.line([tuple(pixels[parent]), tuple(pixels[child])], fill=(90, 60, 30), width=int(widths[child]))
    if leaves and skeleton.n_leaves:
        centres = (skeleton.leaf_corners().mean(1)[:, [0, 2]] - low) / span * (size - 20) + 10
        centres[:, 1] = size - centres[:, 1]
        draw.point([tuple(p) for p in centres], fill=(0, 140, 0))
    draw.text((4, 4), title, fill="black")
    return image


def save_sheet(tiles: list[Image.Image], columns: int, path) -> None:
    """Paste equal-size tiles row by row, `columns` wide, onto one white sheet saved as PNG at `path`."""
    width, height = tiles[0].size
    sheet = Image.new("RGB", (columns * width, -(-len(tiles) // columns) * height), "white")
    for k, tile in enumerate(tiles):
        sheet.paste(tile, ((k % columns) * width, (k // columns) * height))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(png_bytes(np.asarray(sheet)))
