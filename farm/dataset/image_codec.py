"""PNG encoding of rendered maps for the views table: uint8 maps as 8-bit PNG, float maps as 16-bit PNG.

A float map is stored as pixel values p (uint16) with per-image `scale` and `offset`: value = offset + scale * p,
except that p = 0 decodes to 0. A metric map (metres, 0 = background) fits the 16-bit range to each image's
foreground, so precision follows the tree's size, and keeps pixel 0 for its background; every other float map lies
in [0, 1], with scale 1/65535 and offset 0 (so its p = 0 is 0 anyway). Which outputs are metric is the renderers'
declaration (`renderers.OUTPUTS`), passed in by the writer; a reader needs only the stored scale and offset.
Encoding is deterministic (libpng via OpenCV, fixed compression level, no timestamps or text chunks).
`encode_pixels` is the codec's PNG writer for pixels already quantized (`farm render` writes its map files with
it). Pictures that are not maps (textures, thumbnails, contact sheets) go through `species.meshing.png`.
"""
from __future__ import annotations

import numpy as np

from species.errors import TreefarmError

__all__ = ["encode_map", "decode_map", "encode_pixels", "ImageCodecError", "PNG_COMPRESSION"]

PNG_COMPRESSION = 3
_UINT16_MAX = 65535


class ImageCodecError(TreefarmError):
    """A map has a dtype, shape or value range the views table cannot store."""


def _cv2():
    import cv2

    return cv2


def encode_pixels(pixels: np.ndarray, compression: int | None = PNG_COMPRESSION) -> bytes:
    """PNG bytes of (H, W) grey or (H, W, 3) RGB pixels, uint8 (8-bit PNG) or uint16 (16-bit PNG), as they are.

    compression : zlib level 0-9, or None for OpenCV's own default settings (what the library previews use).
    """
    pixels = np.asarray(pixels)
    if pixels.dtype not in (np.uint8, np.uint16) or pixels.ndim not in (2, 3) \
            or (pixels.ndim == 3 and pixels.shape[2] != 3):
        raise ImageCodecError(f"pixels of shape {pixels.shape}, dtype {pixels.dtype} are invalid: allowed "
                              f"(H, W) or (H, W, 3), uint8 or uint16")
    # OpenCV writes 3-channel arrays as BGR; reverse so the file is RGB for every other reader.
    if pixels.ndim == 3:
        pixels = np.ascontiguousarray(pixels[..., ::-1])
    settings = [] if compression is None else [_cv2().IMWRITE_PNG_COMPRESSION, compression]
    ok, buffer = _cv2().imencode(".png", pixels, settings)
    if not ok:
        raise ImageCodecError(f"PNG encoding failed for an array of shape {pixels.shape}, dtype {pixels.dtype}")
    return buffer.tobytes()


def encode_map(name: str, image: np.ndarray, metric: bool = False) -> tuple[bytes, float | None, float | None]:
    """One rendered map as (PNG bytes, scale, offset); scale and offset are None for uint8 maps.

    name   : the output's name, for messages.
    image  : (H, W) or (H, W, 3); uint8 (stored as is) or float32 (stored as 16-bit).
    metric : a float map in metres with 0 = background (`renderers.OUTPUTS[name].metric`); otherwise a float map
             holds values in [0, 1].
    """
    image = np.asarray(image)
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise ImageCodecError(f"map {name!r} has shape {image.shape}; allowed (H, W) or (H, W, 3)")
    if image.dtype == np.uint8:
        return encode_pixels(image), None, None
    if not np.issubdtype(image.dtype, np.floating):
        raise ImageCodecError(f"map {name!r} has dtype {image.dtype}; allowed uint8 or float32")
    if not np.all(np.isfinite(image)):
        raise ImageCodecError(f"map {name!r} contains NaN or infinity")
    values = image.astype(np.float64)
    if metric:
        foreground = values > 0
        if not foreground.any():
            return encode_pixels(np.zeros(image.shape, np.uint16)), 1.0, 0.0
        low, high = values[foreground].min(), values[foreground].max()
        scale = max((high - low) / (_UINT16_MAX - 1), 1e-9)
        offset = low - scale  # pixel 1 is the nearest foreground value; pixel 0 stays background
        pixels = np.where(foreground, np.rint((values - offset) / scale), 0)
        return encode_pixels(np.clip(pixels, 0, _UINT16_MAX).astype(np.uint16)), float(scale), float(offset)
    if values.min() < -1e-6 or values.max() > 1 + 1e-6:
        raise ImageCodecError(f"map {name!r} has values in [{values.min():.4g}, {values.max():.4g}]; "
                              f"allowed [0, 1] for a non-metric float map")
    pixels = np.rint(np.clip(values, 0, 1) * _UINT16_MAX).astype(np.uint16)
    return encode_pixels(pixels), 1.0 / _UINT16_MAX, 0.0


def decode_map(png: bytes, scale: float | None = None, offset: float | None = None) -> np.ndarray:
    """Inverse of `encode_map`: uint8 array for 8-bit PNGs, float32 (offset + scale * p, and 0 where p = 0: a metric
    map's background) for 16-bit ones."""
    cv2 = _cv2()
    pixels = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_UNCHANGED)
    if pixels is None:
        raise ImageCodecError("bytes are not a readable PNG image")
    if pixels.ndim == 3:
        pixels = pixels[..., ::-1]
    if pixels.dtype == np.uint8:
        return np.ascontiguousarray(pixels)
    if scale is None or offset is None:
        raise ImageCodecError("a 16-bit map needs its scale and offset to decode")
    values = (offset + scale * pixels.astype(np.float64)).astype(np.float32)
    values[pixels == 0] = 0.0
    return values
