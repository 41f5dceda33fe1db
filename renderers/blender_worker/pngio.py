"""Grey PNG writing (8- and 16-bit) from numpy arrays, exact (no colour management, no dithering).

Blender's own image writer runs pixels through colour management; masks and depth must keep their values.
"""
from __future__ import annotations

import struct
import zlib

import numpy as np

__all__ = ["write_grey_png"]


def _chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def write_grey_png(path: str, image: np.ndarray) -> None:
    """Write (H, W) uint8 or uint16 as a greyscale PNG of that bit depth (rows top to bottom)."""
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"write_grey_png needs (H, W) uint8 or uint16; got {image.shape} {image.dtype}")
    height, width = image.shape
    depth = 8 if image.dtype == np.uint8 else 16
    rows = image.astype(">u2") if depth == 16 else image
    raw = np.concatenate([np.zeros((height, 1), np.uint8), rows.view(np.uint8).reshape(height, -1)], axis=1)
    header = struct.pack(">IIBBBBB", width, height, depth, 0, 0, 0, 0)
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header)
                + _chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + _chunk(b"IEND", b""))
