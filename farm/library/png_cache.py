"""PNG encoding for library files: a fast zlib level, and each distinct image encoded once (textures repeat
across a species' assets and across an asset's GLB and USD files).

In: (H, W, 3|4) uint8 images. Out: PNG bytes from `species.meshing.png.png_bytes`, the same bytes for the same
pixels (no metadata, fixed level). A `PngCache` is made by whoever writes library files (one per library worker,
`farm.library.job.LibraryChain`) and passed to every writer that embeds or writes a texture.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict

import numpy as np

from species.meshing.png import png_bytes

__all__ = ["PngCache", "PNG_COMPRESS_LEVEL", "CACHE_ENTRIES"]

# zlib level 2: far faster than level 9 for slightly larger files (`benchmarks/bench_png.py` measures both).
PNG_COMPRESS_LEVEL = 2
# Distinct images kept (a species' bark maps and leaf atlases, one asset's impostor and previews).
CACHE_ENTRIES = 64


class PngCache:
    """PNG bytes of images at one zlib level, the `entries` most recently used kept by their pixels."""

    def __init__(self, entries: int = CACHE_ENTRIES, compress_level: int = PNG_COMPRESS_LEVEL) -> None:
        self.entries, self.compress_level = entries, compress_level
        self._encoded: OrderedDict[bytes, bytes] = OrderedDict()

    def __len__(self) -> int:
        return len(self._encoded)

    def encode(self, image: np.ndarray, palette: bool = False) -> bytes:
        """PNG bytes of an (H, W, 3) or (H, W, 4) uint8 image, from the cache when these pixels were seen
        (`palette`: see `png_bytes`)."""
        image = np.ascontiguousarray(image)
        digest = hashlib.blake2b(f"{image.dtype.str}{image.shape}{'P' if palette else ''}".encode(), digest_size=20)
        digest.update(image.data)
        key = digest.digest()
        if key in self._encoded:
            self._encoded.move_to_end(key)
            return self._encoded[key]
        data = png_bytes(image, self.compress_level, palette)
        self._encoded[key] = data
        if len(self._encoded) > self.entries:
            self._encoded.popitem(last=False)
        return data
