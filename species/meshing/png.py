"""PNG encoding of 8-bit pictures: the one encoder of every texture, thumbnail and contact sheet file.

In: an (H, W, 3) or (H, W, 4) uint8 image and a zlib level. Out: PNG bytes with no metadata and no timestamp,
the same bytes for the same pixels and level. Truecolour images are written here with zlib, byte for byte as
Pillow writes them (its per-row filter choice, its deflate settings and IDAT chunk size), without importing
Pillow (start-up time of the commands that write a texture or two); indexed colour and level 0 go through
Pillow. (Rendered maps of the dataset, 16-bit included, have their own codec, `farm.dataset.image_codec`; the
Blender worker writes its own PNGs inside Blender's Python.)
"""
from __future__ import annotations

import io
import struct
import zlib

import numpy as np

from ..errors import ParameterError

__all__ = ["png_bytes"]


def png_bytes(image: np.ndarray, compress_level: int = 9, palette: bool = False) -> bytes:
    """PNG encoding of an (H, W, 3) RGB or (H, W, 4) RGBA uint8 image at zlib level `compress_level` (0-9: 9 the
    smallest files, lower levels faster); no metadata, no timestamp, same bytes each call. With `palette`, an
    image of at most 256 colours is written as indexed colour (alpha in the palette's tRNS): the same pixels
    for a byte per texel, a fraction of the file for flat-coloured atlases."""
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ParameterError("image", f"array {image.dtype} {image.shape}", "(H, W, 3) or (H, W, 4) uint8")
    if isinstance(compress_level, bool) or not isinstance(compress_level, (int, np.integer)) \
            or not 0 <= compress_level <= 9:
        raise ParameterError("compress_level", compress_level, "an integer in [0, 9]")
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
            extra = {"transparency": colours[:, 3].astype(np.uint8).tobytes()} if image.shape[2] == 4 else {}
            return _pillow_png(index.reshape(image.shape[:2]), compress_level,
                               colours[:, :3].astype(np.uint8).tobytes(), **extra)
    if compress_level == 0:  # stored blocks: Pillow's split into blocks follows its rows and buffers
        return _pillow_png(image, compress_level)
    stream = _truecolour_stream(image, compress_level)
    size = _idat_size(image)
    if len(stream) % size == 0:  # Pillow may end such a stream with an empty IDAT: it writes this one
        return _pillow_png(image, compress_level)
    height, width, channels = image.shape
    chunks = [_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6 if channels == 4 else 2, 0, 0, 0))]
    chunks += [_chunk(b"IDAT", stream[start:start + size]) for start in range(0, len(stream), size)]
    return _SIGNATURE + b"".join(chunks) + _chunk(b"IEND", b"")


_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _pillow_png(image: np.ndarray, compress_level: int, palette: bytes | None = None, **extra) -> bytes:
    """Pillow's PNG of an RGB or RGBA image, or of an (H, W) index image with `palette` (RGB bytes)."""
    from PIL import Image  # here, not at the top: start-up time of the commands that write truecolour only

    picture = Image.fromarray(image, mode="P" if palette is not None else "RGBA" if image.shape[2] == 4 else "RGB")
    if palette is not None:
        picture.putpalette(palette)
    buffer = io.BytesIO()
    picture.save(buffer, format="PNG", compress_level=compress_level, **extra)
    return buffer.getvalue()


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def _idat_size(image: np.ndarray) -> int:
    """Bytes of compressed data per IDAT chunk, as Pillow's encoder hands them out (its MAXBLOCK or 4 per column)."""
    return max(65536, image.shape[1] * 4)


def _truecolour_stream(image: np.ndarray, compress_level: int) -> bytes:
    """The zlib stream of an (H, W, C) uint8 image's filtered rows. Each row gets the filter of None, Up, Sub and
    Paeth (PNG types 0, 2, 1, 4: the order Pillow tries them, an earlier one kept on a tie) whose bytes, read as
    signed, sum to the least magnitude; deflate with a 32 KiB window, memory level 9 and the filtered strategy."""
    height, width, channels = image.shape
    rows = np.ascontiguousarray(image).reshape(height, width * channels).astype(np.int16)
    above = np.zeros_like(rows)
    above[1:] = rows[:-1]
    left = np.zeros_like(rows)
    left[:, channels:] = rows[:, :-channels]
    above_left = np.zeros_like(rows)
    above_left[:, channels:] = above[:, :-channels]
    far_above, far_left = np.abs(above - above_left), np.abs(left - above_left)
    far_both = np.abs(left + above - 2 * above_left)
    paeth = np.where((far_above <= far_left) & (far_above <= far_both), left,
                     np.where(far_left <= far_both, above, above_left))
    filtered = np.stack([rows, rows - above, rows - left, rows - paeth]).astype(np.uint8)  # modulo 256
    cost = np.minimum(filtered, 256 - filtered.astype(np.int16)).sum(axis=2)          # (4, H)
    choice = np.argmin(cost, axis=0)
    lines = np.empty((height, width * channels + 1), np.uint8)
    lines[:, 0] = np.array([0, 2, 1, 4], np.uint8)[choice]
    lines[:, 1:] = filtered[choice, np.arange(height)]
    deflate = zlib.compressobj(compress_level, zlib.DEFLATED, 15, 9, zlib.Z_FILTERED)
    return deflate.compress(lines.tobytes()) + deflate.flush()


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
