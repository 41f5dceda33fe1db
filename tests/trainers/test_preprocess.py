"""trainers.preprocess: a drawing of any size and polarity reaches the network as the training renders do."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from trainers.preprocess import PreprocessError, apply_crop, ground_line, ink_mask, prepare, preprocess

# A small tree drawing in unit coordinates: trunk, three branches, a crown ellipse.
_SEGMENTS = np.array([[0.5, 1.0, 0.5, 0.45], [0.5, 0.6, 0.25, 0.3], [0.5, 0.55, 0.75, 0.25], [0.5, 0.45, 0.5, 0.05]])


def _drawing(canvas: tuple[int, int], x0: float, y0: float, side: float, thickness: int, ink=0, paper=255):
    image = np.full(canvas, paper, np.uint8)
    s = 16  # 4 bits of sub-pixel precision
    for a in _SEGMENTS:
        p0 = (int(round((x0 + a[0] * side) * s)), int(round((y0 + a[1] * side) * s)))
        p1 = (int(round((x0 + a[2] * side) * s)), int(round((y0 + a[3] * side) * s)))
        cv2.line(image, p0, p1, ink, thickness, cv2.LINE_AA, 4)
    centre = (int((x0 + 0.5 * side) * s), int((y0 + 0.3 * side) * s))
    cv2.ellipse(image, centre, (int(0.35 * side * s), int(0.28 * side * s)), 0, 0, 360, ink, thickness,
                cv2.LINE_AA, 4)
    return image


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.max(axis=0) > 0.5, b.max(axis=0) > 0.5
    return float((a & b).sum() / (a | b).sum())


def test_output_shape_range_and_polarity():
    image = _drawing((256, 256), 10, 10, 236, 4)
    x = preprocess(image, "sketch", 224)
    assert x.shape == (1, 224, 224) and x.dtype == np.float32
    assert x.min() == 0.0 and x.max() == pytest.approx(1.0)
    # Ink on zero paper: the drawing's pixels are few and bright, the page dark.
    assert 0.02 < (x > 0.5).mean() < 0.2
    assert x[0, 0, 0] == 0.0


def test_small_drawing_in_a_corner_matches_the_same_drawing_filling_the_image():
    filling = preprocess(_drawing((256, 256), 10, 10, 236, 8), "sketch", 256)
    # Drawn at half the size (lines in proportion), low in the corner of a canvas 2000 px wide.
    corner = preprocess(_drawing((1500, 2000), 40, 1340, 118, 4), "sketch", 256)
    assert _iou(filling, corner) > 0.8
    # And drawn much bigger than the network input, on a big page.
    big = preprocess(_drawing((3000, 2400), 300, 500, 1800, 61), "sketch", 256)
    assert _iou(filling, big) > 0.8


def test_inverted_polarity_gives_the_same_input():
    dark_on_light = _drawing((600, 500), 50, 80, 400, 8)
    light_on_dark = 255 - dark_on_light
    np.testing.assert_allclose(preprocess(light_on_dark, "sketch", 128), preprocess(dark_on_light, "sketch", 128),
                               atol=1e-5)


def test_grey_scan_with_noise_and_rgba_tablet_export():
    clean = preprocess(_drawing((400, 400), 20, 20, 360, 6), "sketch", 128)
    rng = np.random.default_rng(0)
    scan = _drawing((400, 400), 20, 20, 360, 6, ink=70, paper=225).astype(np.float64)
    scan = np.clip(scan + rng.normal(0, 4, scan.shape), 0, 255).astype(np.uint8)
    scan = np.repeat(scan[..., None], 3, axis=2)  # an RGB scan
    assert _iou(preprocess(scan, "sketch", 128), clean) > 0.85
    # A tablet export: black RGB everywhere, the strokes in alpha.
    alpha = 255 - _drawing((400, 400), 20, 20, 360, 6)
    rgba = np.dstack([np.zeros((400, 400, 3), np.uint8), alpha])
    assert _iou(preprocess(rgba, "sketch", 128), clean) > 0.95
    # Float input in [0, 1] reads as the same picture.
    np.testing.assert_allclose(preprocess(_drawing((400, 400), 20, 20, 360, 6) / 255.0, "sketch", 128), clean,
                               atol=1e-5)


def test_fine_pen_on_a_big_scan_is_widened_not_faded():
    x = preprocess(_drawing((3000, 3000), 100, 100, 2800, 3), "sketch", 256)
    # Shrunk 11 times, a 3 px line would average to a third of ink; widened first, it keeps a full-ink core.
    assert (x[0] > 0.5).mean() > 0.01
    assert (x[0] > 0.75).sum() > 500 and x.max() > 0.95


def test_colour_strokes_keep_their_colour_on_any_paper():
    image = np.full((300, 300, 3), 255, np.uint8)
    cv2.line(image, (150, 290), (150, 100), (255, 0, 0), 8)
    cv2.line(image, (150, 180), (60, 60), (0, 191, 0), 8)
    x = preprocess(image, "strokes", 256)
    assert x.shape == (3, 256, 256)
    # Ink = 1 - RGB: the red trunk (0, 1, 1), the green branch (1, 0.25, 1); nothing else is fully inked.
    full = x[:, x.max(axis=0) > 0.99].T
    red = np.abs(full - [0.0, 1.0, 1.0]).max(axis=1) < 0.05
    green = np.abs(full - [1.0, 64 / 255, 1.0]).max(axis=1) < 0.05
    assert red.sum() > 500 and green.sum() > 500 and (red | green).mean() > 0.95
    # The same strokes on a black canvas: the paper becomes white, the hues stay (not inverted).
    dark = image.copy()
    dark[(image == 255).all(axis=2)] = 0
    np.testing.assert_allclose(preprocess(dark, "strokes", 256), x, atol=0.02)


def test_crop_cuts_a_target_of_the_same_view_alike():
    image = _drawing((300, 300), 120, 150, 120, 3)
    prepared = prepare(image, "sketch", 64)
    target = (image < 128).astype(np.float32)  # a map aligned with the drawing
    cut = apply_crop(target, prepared.crop, 64, 0.0)
    assert _iou(prepared.image, cut[None]) > 0.6
    # The crop maps network pixels back to the source: the centre lands on the drawing's box centre.
    centre = prepared.crop.to_source(np.array([[31.5, 31.5]]), 64)[0]
    rows, cols = np.nonzero(image < 128)
    assert abs(centre[0] - (cols.min() + cols.max()) / 2) < 2 and abs(centre[1] - (rows.min() + rows.max()) / 2) < 2


@pytest.mark.parametrize("image", [np.full((256, 256), 255, np.uint8), np.zeros((64, 64, 3), np.uint8),
                                   np.full((100, 120, 4), 200, np.uint8), np.full((50, 50), 0.7, np.float32)])
def test_blank_image_is_refused(image):
    with pytest.raises(PreprocessError, match="blank"):
        preprocess(image, "sketch", 128)


@pytest.mark.parametrize("args, match", [
    ((np.zeros((4, 4, 2), np.uint8), "sketch", 64), "shape"),
    ((np.zeros((64, 64), np.int32), "sketch", 64), "dtype"),
    ((np.full((64, 64), 2.0), "sketch", 64), r"\[0, 1\]"),
    ((np.zeros((64, 64), np.uint8), "painting", 64), "kind 'painting'"),
    ((np.zeros((64, 64), np.uint8), "sketch", 3), "size 3"),
])
def test_bad_input_is_refused_naming_the_value(args, match):
    with pytest.raises(PreprocessError, match=match):
        preprocess(*args)


def _lollipop() -> np.ndarray:
    """A cloud on a stick as people draw it: a round crown, the trunk two lines open at the foot."""
    image = np.full((300, 300), 255, np.uint8)
    cv2.circle(image, (150, 90), 70, 0, 3, cv2.LINE_AA)
    for x in (138, 162):
        cv2.line(image, (x, 158), (x, 260), 0, 3, cv2.LINE_AA)
    return image


def test_a_ground_line_under_the_tree_is_left_out_and_the_tree_s_own_foot_is_not():
    """People draw the ground as a long line under the trunk; the renders have none. The tree's own foot (a short
    line closing the trunk, roots spreading from it) and a tree without ground keep every stroke."""
    tree = _lollipop()
    grounded = tree.copy()
    cv2.line(grounded, (10, 262), (290, 258), 0, 3, cv2.LINE_AA)  # under the trunk, far beyond it
    ground = ground_line(grounded < 128)
    assert ground.any() and not ground[:240].any()
    kept, drawn = ink_mask(grounded), ink_mask(tree)
    for axis in (0, 1):  # the drawing's box is the tree's, not the ground's
        box, tree_box = np.flatnonzero(kept.any(axis=axis)), np.flatnonzero(drawn.any(axis=axis))
        assert abs(box[0] - tree_box[0]) <= 6 and abs(box[-1] - tree_box[-1]) <= 6  # a stroke
    ours, theirs = prepare(grounded, "sketch", 128), prepare(tree, "sketch", 128)
    assert np.allclose([ours.crop.x0, ours.crop.y0, ours.crop.side], [theirs.crop.x0, theirs.crop.y0,
                                                                      theirs.crop.side], atol=6)
    assert ours.image[:, -8:, :40].max() < 0.05  # no trace of the line beside the trunk
    assert not ground_line(tree < 128).any()
    footed = tree.copy()
    cv2.line(footed, (130, 261), (170, 261), 0, 3, cv2.LINE_AA)  # the trunk closed at its foot
    rooted = tree.copy()
    for x, out in ((138, -1), (162, 1)):  # roots from each side of the trunk, out and down, ending flat
        cv2.line(rooted, (x, 240), (x + out * 30, 268), 0, 3, cv2.LINE_AA)
        cv2.line(rooted, (x + out * 30, 268), (x + out * 80, 270), 0, 3, cv2.LINE_AA)
    for kept in (footed, rooted):
        assert not ground_line(kept < 128).any()
