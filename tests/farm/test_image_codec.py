"""PNG codec of the views table: exact uint8 round trips, 16-bit float maps within one step, deterministic bytes."""
from __future__ import annotations

import io

import numpy as np
import pytest
from PIL import Image

from farm.dataset.image_codec import ImageCodecError, decode_map, encode_map, encode_pixels


def test_uint8_rgb_map_round_trips_exactly_in_rgb_order():
    image = np.random.default_rng(0).integers(0, 256, (20, 30, 3), dtype=np.uint8)
    png, scale, offset = encode_map("trunk_strokes", image)
    assert scale is None and offset is None
    np.testing.assert_array_equal(decode_map(png), image)
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(png))), image)  # any PNG reader agrees


def test_metric_depth_round_trips_within_one_step_and_keeps_background_zero():
    depth = np.random.default_rng(1).uniform(3.0, 9.0, (16, 16)).astype(np.float32)
    depth[:4] = 0.0
    png, scale, offset = encode_map("depth", depth, metric=True)
    assert Image.open(io.BytesIO(png)).mode.startswith("I;16")
    assert offset != 0  # the 16-bit range starts at the nearest foreground depth
    back = decode_map(png, scale, offset)
    assert np.all(back[:4] == 0)
    assert np.max(np.abs(back[4:] - depth[4:])) <= scale


def test_unit_range_float_map_round_trips_within_one_sixteen_bit_step():
    image = np.random.default_rng(2).uniform(0, 1, (8, 8, 3)).astype(np.float32)
    png, scale, offset = encode_map("silhouette", image)
    assert np.max(np.abs(decode_map(png, scale, offset) - image)) <= 1 / 65535


def test_encoding_is_deterministic():
    image = np.random.default_rng(3).uniform(0, 1, (8, 8)).astype(np.float32)
    assert encode_map("trunk_depth", image) == encode_map("trunk_depth", image.copy())


@pytest.mark.parametrize("name, image", [
    ("trunk_depth", np.full((4, 4), 1.5, np.float32)),
    ("mask", np.zeros((4, 4, 2), np.uint8)),
    ("mask", np.zeros((4, 4), np.int64)),
    ("depth", np.full((4, 4), np.nan, np.float32)),
])
def test_unstorable_map_is_rejected(name, image):
    with pytest.raises(ImageCodecError, match=name):
        encode_map(name, image)


@pytest.mark.parametrize("pixels", [np.arange(12, dtype=np.uint16).reshape(3, 4) * 5000,
                                    np.arange(36, dtype=np.uint8).reshape(3, 4, 3)])
def test_quantized_pixels_are_written_as_they_are(pixels):
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(encode_pixels(pixels)))), pixels)


@pytest.mark.parametrize("pixels", [np.zeros((3, 4), np.float32), np.zeros((3, 4, 4), np.uint8)])
def test_pixels_of_another_dtype_or_channel_count_are_rejected(pixels):
    with pytest.raises(ImageCodecError, match="allowed"):
        encode_pixels(pixels)


def test_a_unit_range_map_is_stored_with_offset_zero_so_its_pixel_zero_is_zero_as_a_metric_background():
    image = np.random.default_rng(4).uniform(0, 1, (8, 8)).astype(np.float32)
    image[0] = 0.0
    png, scale, offset = encode_map("trunk_depth", image)
    assert (scale, offset) == (1 / 65535, 0.0)
    assert np.all(decode_map(png, scale, offset)[0] == 0)
