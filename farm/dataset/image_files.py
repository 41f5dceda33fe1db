"""Image files a user gives (drawings, photos) read as arrays: the one reader that reconstruction, evaluation and
training inputs share. Maps inside the dataset go through `image_codec` instead.

Every kind comes back in one form, so that what reads the array next (a method, a contact sheet, a report panel,
the networks' preprocessing) never meets an alpha channel, a palette or a 16-bit range: 8-bit grey stays grey,
16-bit grey and colour are scaled to 8 bits, transparency (an alpha channel, a palette's or a PNG's transparent
colour) is laid over white paper, palettes and other colour spaces become RGB.
"""
from __future__ import annotations

import numpy as np
from PIL import Image, UnidentifiedImageError

from species.errors import PathError, user_path

__all__ = ["read_image", "IMAGE_SUFFIXES"]

# The file names taken for images where a folder is scanned (`farm evaluate --inputs`).
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".webp")

# PIL modes of one grey channel: 16-bit (in several byte orders) and 32-bit integer (how some formats hand over
# 16-bit greys), then 8-bit and bi-level.
_WIDE_GREY_MODES = ("I", "I;16", "I;16B", "I;16L", "I;16N")
_GREY_MODES = _WIDE_GREY_MODES + ("L", "1")
_GREY_ALPHA_MODES = ("LA", "La")
_PAPER = 255.0  # transparent pixels show white paper


def _on_paper(pixels: np.ndarray) -> np.ndarray:
    """uint8 colour or grey channels of a (H, W, C + 1) uint8 array whose last channel is alpha, laid over white."""
    alpha = pixels[..., -1:].astype(np.float32) / 255.0
    colour = pixels[..., :-1].astype(np.float32)
    laid = np.rint(colour * alpha + _PAPER * (1.0 - alpha)).astype(np.uint8)
    return laid[..., 0] if laid.shape[2] == 1 else laid


def _as_array(image: Image.Image, path) -> np.ndarray:
    """The uint8 (H, W) or (H, W, 3) array of a loaded PIL image (see `read_image`)."""
    transparent = "transparency" in image.info
    if image.mode in _WIDE_GREY_MODES:
        wide = np.asarray(image).astype(np.float64)
        return np.rint(np.clip(wide, 0, 65535) / 257.0).astype(np.uint8)
    if image.mode in _GREY_MODES and not transparent:
        return np.asarray(image.convert("L"))
    if image.mode in _GREY_MODES or image.mode in _GREY_ALPHA_MODES:
        return _on_paper(np.asarray(image.convert("LA")))
    if image.mode == "RGB" and not transparent:
        return np.asarray(image)
    if "A" in image.mode or transparent:  # RGBA, RGBa, PA, a palette or RGB with a transparent colour
        return _on_paper(np.asarray(image.convert("RGBA")))
    if image.mode == "F":
        raise PathError(f"{path} holds floating-point pixels: allowed 8- or 16-bit images")
    return np.asarray(image.convert("RGB"))  # a palette without transparency, CMYK, YCbCr, LAB, HSV


def read_image(path) -> np.ndarray:
    """An image file as a uint8 array: (H, W) for a grey image, (H, W, 3) RGB for any other, never an alpha channel.

    Accepted: PNG (8- and 16-bit grey, grey with alpha, RGB, RGBA, palettes with or without transparency), JPEG
    (grey, RGB, CMYK), TIFF, BMP and WebP. 16-bit values are scaled to 0-255 (65535 -> 255); transparent pixels are
    composited over white paper by their alpha (a drawing on a transparent background reads as ink on white).
    PathError (one line) for a file that is missing, unreadable or not an image."""
    with user_path(path, "read"):
        try:
            with Image.open(path) as image:
                image.load()
                return _as_array(image, path)
        except UnidentifiedImageError:
            raise PathError(f"{path} is not an image file: allowed PNG, JPEG, TIFF, BMP or WebP") from None
