"""Specification of species.meshing.textures and .png: tileable bark, a leaf with alpha, deterministic PNGs."""
import io

import numpy as np
import pytest
from PIL import Image

from species.errors import ParameterError
from species.meshing.png import png_bytes
from species.meshing.textures import (BARK_TEXTURE_SEED, bark_colour, bark_png, bark_texture, fissure_depth, leaf_png,
                                      leaf_texture)

BARK = (0.36, 0.27, 0.19)
LEAF = (0.24, 0.45, 0.14)


def _bark():
    return bark_texture(BARK, np.random.default_rng(BARK_TEXTURE_SEED)).astype(np.float64)


def test_bark_is_rgb_uint8_of_the_requested_size():
    image = bark_texture(BARK, np.random.default_rng(0), height=64, width=32)
    assert image.shape == (64, 32, 3) and image.dtype == np.uint8


def test_bark_tiles_seamlessly_in_both_directions():
    image = _bark()
    inner_rows = np.abs(np.diff(image, axis=0)).mean()
    inner_cols = np.abs(np.diff(image, axis=1)).mean()
    assert np.abs(image[0] - image[-1]).mean() < 2 * inner_rows
    assert np.abs(image[:, 0] - image[:, -1]).mean() < 2 * inner_cols


def test_bark_fissures_run_along_the_branch():
    # Neighbours along v (rows) are more alike than neighbours around u (columns).
    image = _bark()
    assert np.abs(np.diff(image, axis=0)).mean() < np.abs(np.diff(image, axis=1)).mean()


def test_bark_average_is_near_its_base_colour():
    mean = _bark().mean(axis=(0, 1)) / 255
    srgb = np.where(np.array(BARK) <= 0.0031308, 12.92 * np.array(BARK), 1.055 * np.array(BARK) ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(mean, srgb, atol=0.12)


def test_leaf_is_opaque_in_the_middle_and_clear_in_the_corners():
    image = leaf_texture(LEAF, size=128)
    assert image.shape == (128, 128, 4) and image.dtype == np.uint8
    assert image[64, 64, 3] == 255 and image[60, 40, 3] == 255
    assert image[0, 0, 3] == image[0, -1, 3] == image[-1, 0, 3] == image[-1, -1, 3] == 0
    assert 0.3 < (image[..., 3] > 127).mean() < 0.8


def test_pngs_decode_to_the_arrays_and_are_identical_each_call():
    leaf = leaf_texture(LEAF)
    data = png_bytes(leaf)
    assert data == png_bytes(leaf)
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(data))), leaf)
    assert bark_png(BARK) == bark_png(list(BARK)) and leaf_png(LEAF)[:8] == b"\x89PNG\r\n\x1a\n"


def test_texture_pngs_at_a_fast_level_hold_the_same_pixels():
    for made, image in ((leaf_png, leaf_texture(LEAF)), (bark_png, bark_texture(BARK, np.random.default_rng(
            BARK_TEXTURE_SEED)))):
        colour = LEAF if made is leaf_png else BARK
        fast, small = made(colour, 2), made(colour)
        assert fast == png_bytes(image, 2) and small == png_bytes(image, 9) and len(fast) >= len(small)
        np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(fast))), image)


def test_out_of_range_colour_is_rejected():
    with pytest.raises(ParameterError, match="color"):
        leaf_texture((1.5, 0, 0))


def test_png_levels_trade_size_for_nothing_else():
    bark = bark_texture(BARK, np.random.default_rng(BARK_TEXTURE_SEED))
    fast, small = png_bytes(bark, compress_level=1), png_bytes(bark)
    assert fast != small and len(small) <= len(fast)
    for data in (fast, small):
        np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(data))), bark)


@pytest.mark.parametrize("image, level, key", [(np.zeros((4, 4), np.uint8), 9, "image"),
                                               (np.zeros((4, 4, 3), np.float32), 9, "image"),
                                               (np.zeros((4, 4, 3), np.uint8), 10, "compress_level"),
                                               (np.zeros((4, 4, 3), np.uint8), 2.0, "compress_level")])
def test_png_of_an_image_or_level_it_cannot_write_is_rejected(image, level, key):
    with pytest.raises(ParameterError, match=key):
        png_bytes(image, compress_level=level)


def test_bark_colour_is_darkest_in_the_fissures_and_the_base_colour_on_flat_bark():
    flat = np.zeros((4, 4))
    plain = bark_colour(BARK, fissure_depth(np.full((4, 4), 10.0), 0.45), flat, flat)
    cracked = bark_colour(BARK, fissure_depth(flat, 0.45), flat, flat)
    assert plain.shape == (4, 4, 3) and plain.dtype == np.uint8
    assert (cracked < plain).all()



@pytest.mark.parametrize("shape, level", [((256, 128, 3), 9), ((128, 128, 4), 9), ((300, 400, 3), 6),
                                          ((1, 20000, 4), 1), ((97, 33, 3), 9), ((5, 7, 3), 0)])
def test_truecolour_pngs_are_pillows_bytes(shape, level):
    # noise (several IDAT chunks at the larger sizes, one row wider than Pillow's block) and flat runs (the
    # filters tie), against Pillow's own encoding of the same pixels
    rng = np.random.default_rng(3)
    image = rng.integers(0, 256, shape, dtype=np.uint8)
    image[: shape[0] // 2] = rng.integers(0, 4, shape[1:], dtype=np.uint8) * 60
    buffer = io.BytesIO()
    Image.fromarray(image, mode="RGBA" if shape[2] == 4 else "RGB").save(buffer, format="PNG", compress_level=level)
    assert png_bytes(image, level) == buffer.getvalue()
