"""Specification of species.textures: tileable bark, a leaf with alpha, deterministic PNGs."""
import io

import numpy as np
import pytest
from PIL import Image

from species.errors import ParameterError
from species.meshing.textures import BARK_TEXTURE_SEED, bark_png, bark_texture, leaf_png, leaf_texture, png_bytes

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


def test_out_of_range_colour_is_rejected():
    with pytest.raises(ParameterError, match="color"):
        leaf_texture((1.5, 0, 0))
