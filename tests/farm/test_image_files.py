"""farm.dataset.read_image: the image files users give, as the arrays every reader of them gets: uint8, (H, W) grey
or (H, W, 3) RGB, transparency laid over white paper, 16 bits scaled to 8."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from farm.dataset import read_image
from species.errors import PathError

REAL_DRAWINGS = Path(__file__).resolve().parents[3] / "shared" / "data" / "sketches" / "mouse_branches_foliage"

GREY = np.arange(48, dtype=np.uint8).reshape(6, 8) * 5
RGB = np.dstack([GREY, GREY[::-1], 255 - GREY])
ALPHA = np.tile(np.array([0, 255, 128, 0, 255, 64, 255, 0], np.uint8), (6, 1))  # clear, opaque and between


def _read(tmp_path, name: str, image: Image.Image, **save) -> np.ndarray:
    image.save(tmp_path / name, **save)
    back = read_image(tmp_path / name)
    assert back.dtype == np.uint8, name
    return back


def _on_white(values: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    a = (alpha.astype(np.float64) / 255.0)[..., None] if values.ndim == 3 else alpha / 255.0
    return np.rint(values * a + 255.0 * (1.0 - a)).astype(np.uint8)


def test_8_bit_grey_reads_as_it_is(tmp_path):
    assert np.array_equal(_read(tmp_path, "grey.png", Image.fromarray(GREY)), GREY)


def test_16_bit_grey_is_scaled_to_8_bits(tmp_path):
    deep = GREY.astype(np.uint16) * 257 + 100  # 8-bit levels spread over 16 bits, plus less than half a level
    assert np.array_equal(_read(tmp_path, "deep.png", Image.fromarray(deep)), GREY)


def test_8_bit_rgb_reads_as_it_is(tmp_path):
    assert np.array_equal(_read(tmp_path, "rgb.png", Image.fromarray(RGB)), RGB)


def test_16_bit_rgb_is_scaled_to_8_bits(tmp_path):
    cv2.imwrite(str(tmp_path / "deep_rgb.png"), (RGB.astype(np.uint16) * 257)[..., ::-1])  # PIL writes no 16-bit RGB
    back = read_image(tmp_path / "deep_rgb.png")
    assert back.dtype == np.uint8 and np.array_equal(back, RGB)


def test_rgba_is_composited_on_white(tmp_path):
    back = _read(tmp_path, "rgba.png", Image.fromarray(np.dstack([RGB, ALPHA])))
    assert back.shape == RGB.shape and np.array_equal(back, _on_white(RGB, ALPHA))
    assert (back[ALPHA == 0] == 255).all() and np.array_equal(back[ALPHA == 255], RGB[ALPHA == 255])


def test_grey_with_alpha_is_composited_on_white_and_stays_grey(tmp_path):
    back = _read(tmp_path, "grey_alpha.png", Image.fromarray(np.dstack([GREY, ALPHA]), "LA"))
    assert back.shape == GREY.shape and np.array_equal(back, _on_white(GREY, ALPHA))


def test_a_palette_png_reads_as_rgb(tmp_path):
    palette = Image.fromarray(RGB).quantize(256)
    back = _read(tmp_path, "palette.png", palette)
    assert back.shape == RGB.shape and np.array_equal(back, np.asarray(palette.convert("RGB")))


def test_a_palette_png_with_a_transparent_entry_shows_white_there(tmp_path):
    colours = np.zeros((6, 8, 3), np.uint8)
    colours[:, 4:] = (10, 200, 30)  # left half palette entry 0 (black), right half entry 1 (green)
    palette = Image.fromarray(colours).quantize(2)
    clear = int(np.asarray(palette)[0, 0])
    back = _read(tmp_path, "clear.png", palette, transparency=clear)
    assert back.shape == (6, 8, 3)
    assert (back[:, :4] == 255).all() and (back[:, 4:] == (10, 200, 30)).all()


def test_jpeg_grey_and_colour_read_as_grey_and_rgb(tmp_path):
    flat = np.full((16, 16, 3), (40, 120, 220), np.uint8)
    colour = _read(tmp_path, "photo.jpg", Image.fromarray(flat), quality=95)
    assert colour.shape == flat.shape and np.abs(colour.astype(int) - flat).max() <= 3
    grey = _read(tmp_path, "scan.jpeg", Image.fromarray(np.full((16, 16), 90, np.uint8)), quality=95)
    assert grey.shape == (16, 16) and np.abs(grey.astype(int) - 90).max() <= 2


@pytest.mark.skipif(not REAL_DRAWINGS.is_dir(), reason="the real drawings (shared/data/sketches) are absent")
def test_real_rgba_drawings_read_as_coloured_strokes_on_white():
    for path in sorted(REAL_DRAWINGS.glob("*.png")):
        with Image.open(path) as image:
            assert image.mode == "RGBA", path.name  # what the test is about
            alpha = np.asarray(image)[..., 3]
        back = read_image(path)
        assert back.shape == alpha.shape + (3,), path.name
        assert (back[alpha == 0] == 255).all(), path.name  # the transparent background is paper, not black
        assert (back.min(axis=2)[alpha == 255] < 128).all(), path.name  # the strokes stay ink


def test_a_file_that_is_not_an_image_or_is_missing_is_a_one_line_path_error(tmp_path):
    (tmp_path / "notes.png").write_text("not a picture")
    with pytest.raises(PathError, match="is not an image file: allowed PNG"):
        read_image(tmp_path / "notes.png")
    with pytest.raises(PathError, match="cannot read"):
        read_image(tmp_path / "missing.png")
