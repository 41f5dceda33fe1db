"""Image files a user gives (drawings, photos) read as arrays: the one reader that reconstruction, evaluation and
training inputs share. Maps inside the dataset go through `image_codec` instead."""
from __future__ import annotations

import numpy as np
from PIL import Image, UnidentifiedImageError

from species.errors import PathError, user_path

__all__ = ["read_image"]

# PIL modes read as RGB, or as RGBA when they carry transparency: palettes, bi-level, other colour spaces.
_CONVERTED_MODES = ("P", "PA", "CMYK", "YCbCr", "LAB", "HSV", "1", "LA")


def read_image(path) -> np.ndarray:
    """An image file as an array: (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA; 16-bit greys stay uint16.
    PathError (one line) for a file that is missing, unreadable or not an image."""
    with user_path(path, "read"):
        try:
            with Image.open(path) as image:
                image.load()
                if image.mode in _CONVERTED_MODES:
                    image = image.convert("RGBA" if "A" in image.mode or "transparency" in image.info else "RGB")
                return np.asarray(image)
        except UnidentifiedImageError:
            raise PathError(f"{path} is not an image file: allowed PNG, JPEG, TIFF, BMP or WebP") from None
