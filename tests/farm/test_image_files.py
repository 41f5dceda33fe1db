"""farm.dataset.read_image: the image files users give, as the arrays every reader of them gets."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from farm.dataset import read_image
from species.errors import PathError


def test_grey_rgb_and_16_bit_grey_keep_their_shape_and_depth(tmp_path):
    grey = np.arange(48, dtype=np.uint8).reshape(6, 8)
    rgb = np.dstack([grey, grey[::-1], 255 - grey])
    deep = (np.arange(48, dtype=np.uint16) * 1000).reshape(6, 8)
    for name, array in (("grey", grey), ("rgb", rgb), ("deep", deep)):
        Image.fromarray(array).save(tmp_path / f"{name}.png")
        back = read_image(tmp_path / f"{name}.png")
        assert back.dtype == array.dtype and np.array_equal(back, array), name


def test_a_palette_png_reads_as_rgb_and_one_with_transparency_as_rgba(tmp_path):
    palette = Image.fromarray(np.full((4, 4, 3), (10, 200, 30), np.uint8)).convert("P")
    palette.save(tmp_path / "palette.png")
    assert read_image(tmp_path / "palette.png").shape == (4, 4, 3)
    palette.save(tmp_path / "clear.png", transparency=0)
    assert read_image(tmp_path / "clear.png").shape == (4, 4, 4)


def test_a_file_that_is_not_an_image_or_is_missing_is_a_one_line_path_error(tmp_path):
    (tmp_path / "notes.png").write_text("not a picture")
    with pytest.raises(PathError, match="is not an image file: allowed PNG"):
        read_image(tmp_path / "notes.png")
    with pytest.raises(PathError, match="cannot read"):
        read_image(tmp_path / "missing.png")
