"""Sketch styles: black lines on white, ink on the tree and nowhere far from it, deterministic."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

STYLES = ("sketch_tsn", "sketch_edges", "sketch_strokes", "sketch_strokes_brush", "sketch_crown", "sketch_hand")


def _near_tree(view, pixels: int) -> np.ndarray:
    tree = (view.images["mask"] > 0).astype(np.uint8)
    kernel = np.ones((2 * pixels + 1, 2 * pixels + 1), np.uint8)
    return cv2.dilate(tree, kernel) > 0


@pytest.mark.parametrize("style", STYLES)
@pytest.mark.parametrize("rig", ["tsn4", "two-view"])
def test_style_is_black_lines_on_white(all_outputs, style, rig):
    image = all_outputs[rig][0].images[style]
    assert image.dtype == np.uint8 and image.shape == all_outputs[rig][0].images["mask"].shape
    assert np.mean((image == 0) | (image == 255)) > 0.97
    assert np.mean(image == 255) > 0.6


@pytest.mark.parametrize("style", STYLES)
def test_style_inks_the_tree_and_nothing_far_from_it(all_outputs, style):
    view = all_outputs["tsn4"][1]
    ink = view.images[style] < 128
    assert ink.sum() > 50
    # Crown outlines sit a blur radius outside the leaves; hand strokes wobble and over-shoot a little.
    assert not np.any(ink & ~_near_tree(view, 10))
    assert np.mean(ink[_near_tree(view, 1)]) > 0.02


def test_tsn_draws_both_bark_and_crown_lines(all_outputs):
    view = all_outputs["two-view"][0]
    ink = view.images["sketch_tsn"] == 0
    bark = view.images["mask"] == 1
    crown = view.images["sketch_crown"] == 0
    assert np.mean(ink[cv2.dilate(bark.astype(np.uint8), np.ones((3, 3))) > 0]) > 0.2
    assert (ink & ~cv2.dilate(bark.astype(np.uint8), np.ones((5, 5))).astype(bool)).sum() > 20
    assert crown.sum() > 20


def test_brush_strokes_are_wider_than_pen_strokes(all_outputs):
    images = all_outputs["two-view"][0].images
    assert (images["sketch_strokes_brush"] == 0).sum() > 1.5 * (images["sketch_strokes"] == 0).sum()


def test_pen_strokes_are_one_pixel_thin(all_outputs):
    ink = (all_outputs["two-view"][0].images["sketch_strokes"] == 0).astype(np.uint8)
    # A 1-pixel pen leaves almost nothing after an erosion with a 2x2 block.
    assert cv2.erode(ink, np.ones((2, 2), np.uint8)).sum() < 0.1 * ink.sum()


def test_hand_style_changes_with_the_rng_and_repeats_with_it(view_renderer, tree):
    mesh, skeleton = tree
    a, b, c = (view_renderer.render(mesh, skeleton, "two-view", ["sketch_hand"], np.random.default_rng(s))[0]
               for s in (1, 1, 2))
    np.testing.assert_array_equal(a.images["sketch_hand"], b.images["sketch_hand"])
    assert not np.array_equal(a.images["sketch_hand"], c.images["sketch_hand"])
