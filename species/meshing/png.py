"""PNG encoding of 8-bit pictures: the one encoder of every texture, thumbnail and contact sheet file (Pillow).

In: an (H, W, 3) or (H, W, 4) uint8 image and a zlib level. Out: PNG bytes with no metadata and no timestamp,
the same bytes for the same pixels and level. (Rendered maps of the dataset, 16-bit included, have their own
codec, `farm.dataset.image_codec`; the Blender worker writes its own PNGs inside Blender's Python.)
"""
from __future__ import annotations

import io

import numpy as np

from ..errors import ParameterError

__all__ = ["png_bytes"]


def png_bytes(image: np.ndarray, compress_level: int = 9, palette: bool = False) -> bytes:
    """PNG encoding of an (H, W, 3) RGB or (H, W, 4) RGBA uint8 image at zlib level `compress_level` (0-9: 9 the
    smallest files, lower levels faster); no metadata, no timestamp, same bytes each call. With `palette`, an
    image of at most 256 colours is written as indexed colour (alpha in the palette's tRNS): the same pixels
    for a byte per texel, a fraction of the file for flat-coloured atlases."""
    from PIL import Image

    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ParameterError("image", f"array {image.dtype} {image.shape}", "(H, W, 3) or (H, W, 4) uint8")
    if isinstance(compress_level, bool) or not isinstance(compress_level, (int, np.integer)) \
            or not 0 <= compress_level <= 9:
        raise ParameterError("compress_level", compress_level, "an integer in [0, 9]")
    buffer = io.BytesIO()
    if palette:
        # One integer per texel, channels big-endian, so its order is the rows' lexicographic order (same
        # palette as a row-wise unique, which is far slower on an atlas).
        channels = image.shape[2]
        if channels == 4:  # the texel's four bytes read as one big-endian integer: the same keys in one pass
            keys = np.ascontiguousarray(image).view(">u4")[..., 0].astype(np.uint32)
        else:
            keys = np.zeros(image.shape[:2], np.uint32)
            for c in range(channels):
                keys |= image[..., c].astype(np.uint32) << np.uint32(8 * (channels - 1 - c))
        unique_keys, index = _palette_index(keys.ravel())
        if len(unique_keys) <= 256:
            colours = (unique_keys[:, None] >> (8 * np.arange(channels - 1, -1, -1, dtype=np.uint32))) & 0xFF
            indexed = Image.fromarray(index.reshape(image.shape[:2]), mode="P")
            indexed.putpalette(colours[:, :3].astype(np.uint8).tobytes())
            extra = {"transparency": colours[:, 3].astype(np.uint8).tobytes()} if image.shape[2] == 4 else {}
            indexed.save(buffer, format="PNG", compress_level=compress_level, **extra)
            return buffer.getvalue()
    Image.fromarray(image, mode="RGBA" if image.shape[2] == 4 else "RGB").save(
        buffer, format="PNG", compress_level=compress_level)
    return buffer.getvalue()


# Up to this many colours, `_palette_index` finds them by comparisons (a pass over the keys each), not by hashing
# and a binary search per texel, which costs more on an atlas of a few colours.
_FEW_COLOURS = 8


def _palette_index(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """The distinct values of `keys` (N,) uint32, sorted, and each key's rank among them as (N,) uint8; the rank is
    None when there are more than 256 values (no palette holds them)."""
    distinct, pending = [], None
    while len(keys) and len(distinct) <= _FEW_COLOURS:
        first = 0 if pending is None else int(np.argmax(pending))
        if pending is not None and not pending[first]:
            values = np.sort(np.array(distinct, np.uint32))
            index = np.zeros(len(keys), np.uint8)
            for rank, value in enumerate(values[1:], 1):
                index[keys == value] = rank
            return values, index
        distinct.append(keys[first])
        differs = keys != keys[first]
        pending = differs if pending is None else pending & differs
    values = np.sort(np.unique(keys, sorted=False))  # hashed, then the colours sorted
    if len(values) > 256:
        return values, None
    return values, np.searchsorted(values, keys).astype(np.uint8)
