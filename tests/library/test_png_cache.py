"""The library's PNG cache: the species encoder's bytes at the library's level, each distinct image encoded once,
the least recently used dropped first."""
from __future__ import annotations

import numpy as np
import pytest

from farm.library.png_cache import PNG_COMPRESS_LEVEL, PngCache
from species.errors import ParameterError
from species.meshing.png import png_bytes


def _image(seed: int, channels: int = 3) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (16, 8, channels), dtype=np.uint8)


def test_cached_bytes_are_the_encoders_at_the_library_level():
    image = _image(0, 4)
    assert PngCache().encode(image) == png_bytes(image, PNG_COMPRESS_LEVEL)


def test_the_same_pixels_are_encoded_once_whatever_array_holds_them():
    cache = PngCache()
    image = _image(1)
    first = cache.encode(image)
    assert cache.encode(np.asfortranarray(image)) is first and cache.encode(image.copy()) is first
    assert len(cache) == 1


def test_the_least_recently_used_image_is_dropped_first():
    cache = PngCache(entries=2)
    a, b, c = (_image(seed) for seed in range(3))
    first_a = cache.encode(a)
    cache.encode(b)
    cache.encode(a)  # a is now the most recent
    cache.encode(c)  # drops b
    assert len(cache) == 2 and cache.encode(a) is first_a


def test_images_of_the_same_bytes_but_another_shape_are_not_confused():
    cache = PngCache()
    image = _image(2)
    assert cache.encode(image) != cache.encode(image.reshape(8, 16, 3))


def test_an_image_the_encoder_cannot_write_is_rejected_and_not_cached():
    cache = PngCache()
    with pytest.raises(ParameterError, match="image"):
        cache.encode(np.zeros((4, 4, 3), np.float32))
    assert len(cache) == 0


def test_a_read_only_image_is_known_by_identity_but_a_read_only_view_is_hashed_each_time():
    cache = PngCache()
    owned = _image(3, 4)
    owned.flags.writeable = False
    first = cache.encode(owned, palette=True)
    assert cache.encode(owned, palette=True) is first and cache.encode(owned) == png_bytes(owned, PNG_COMPRESS_LEVEL)
    # A read-only view's pixels can still change through its base: its bytes must follow them.
    base = _image(4, 4)
    view = base.view()
    view.flags.writeable = False
    before = cache.encode(view)
    base[0, 0] = 255 - base[0, 0]
    after = cache.encode(view)
    assert after != before and after == png_bytes(base, PNG_COMPRESS_LEVEL)
