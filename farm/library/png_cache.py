"""PNG encoding for library files: a fast zlib level, and each distinct image encoded once (textures repeat
across a species' assets and across an asset's GLB and USD files).

In: (H, W, 3|4) uint8 images. Out: PNG bytes from `species.meshing.png.png_bytes`, the same bytes for the same
pixels (no metadata, fixed level). A `PngCache` is made by whoever writes library files (one per library worker,
`farm.library.job.LibraryChain`) and passed to every writer that embeds or writes a texture.
"""
from __future__ import annotations

import hashlib
import weakref
from collections import OrderedDict

import numpy as np

from species.meshing.png import png_bytes

__all__ = ["PngCache", "PNG_COMPRESS_LEVEL", "CACHE_ENTRIES"]

# zlib level 2: far faster than level 9 for slightly larger files (`python -m benchmarks.bench_png` measures both).
PNG_COMPRESS_LEVEL = 2
# Distinct images kept (a species' bark maps and leaf atlases, one asset's impostor and previews).
CACHE_ENTRIES = 64


class PngCache:
    """PNG bytes of images at one zlib level, the `entries` most recently used kept by their pixels."""

    def __init__(self, entries: int = CACHE_ENTRIES, compress_level: int = PNG_COMPRESS_LEVEL) -> None:
        self.entries, self.compress_level = entries, compress_level
        self._encoded: OrderedDict[bytes, bytes] = OrderedDict()
        # Read-only arrays seen before -> (a weak reference to it, its key): an asset's atlases go into its GLB
        # twice (the file, the size without instancing) and its USD textures, and hashing a large RGBA atlas each
        # time adds up. Only read-only arrays that own their pixels: nothing can change them.
        self._keys: dict[int, tuple[weakref.ref, dict[bool, bytes]]] = {}

    def __len__(self) -> int:
        return len(self._encoded)

    def encode(self, image: np.ndarray, palette: bool = False) -> bytes:
        """PNG bytes of an (H, W, 3) or (H, W, 4) uint8 image, from the cache when these pixels were seen
        (`palette`: see `png_bytes`)."""
        key = self._key(np.ascontiguousarray(image), palette)
        if key in self._encoded:
            self._encoded.move_to_end(key)
            return self._encoded[key]
        data = png_bytes(image, self.compress_level, palette)
        self._encoded[key] = data
        if len(self._encoded) > self.entries:
            self._encoded.popitem(last=False)
        return data

    def _key(self, image: np.ndarray, palette: bool) -> bytes:
        """The cache key of an image's pixels (its dtype, shape and bytes hashed), looked up by identity for a
        read-only array seen before."""
        read_only = not image.flags.writeable and image.base is None  # no other array can change its pixels
        seen = self._keys.get(id(image)) if read_only else None
        if seen is not None and seen[0]() is image and palette in seen[1]:
            return seen[1][palette]
        # SHA-256 runs on the CPU's SHA instructions through OpenSSL: faster than blake2b on the machines it was
        # compared on (an asset's four twig atlas albedos).
        digest = hashlib.sha256(f"{image.dtype.str}{image.shape}{'P' if palette else ''}".encode())
        digest.update(image.data)
        key = digest.digest()
        if read_only:
            if seen is None or seen[0]() is not image:
                ident = id(image)
                seen = self._keys[ident] = (weakref.ref(image, lambda _: self._keys.pop(ident, None)), {})
            seen[1][palette] = key
        return key
