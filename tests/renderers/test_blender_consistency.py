"""Blender (Cycles) and pyrender agree on the same tree and cameras: part masks overlap and depths match.

Leaf cards are rendered whole in Blender here (alpha_cutout=False), as pyrender draws them; the figures are
printed (pytest -s) and named in every failure message.
"""
from __future__ import annotations

import numpy as np
import pytest

from renderers.blender import load_view, render_photos

pytestmark = pytest.mark.slow

MIN_IOU = 0.9
MAX_MEDIAN_DEPTH_ERROR = 0.02  # share of the pyrender depth
MIN_PART_AGREEMENT = 0.95


@pytest.fixture(scope="module")
def pairs(view_renderer, tree, tmp_path_factory):
    """[(pyrender images, blender images)] for the front and right views of the tsn4 rig."""
    mesh, skeleton = tree
    views = view_renderer.render(mesh, skeleton, "tsn4", ["depth", "mask"], np.random.default_rng(0))[:2]
    photos = render_photos(mesh.to_glb(), [v.camera for v in views], tmp_path_factory.mktemp("consistency"),
                           samples=4, alpha_cutout=False)
    return [(v.images, load_view(photos, i)) for i, v in enumerate(views)]


def _figures(ours: dict, blender: dict) -> dict:
    a, b = ours["mask"] > 0, blender["mask"] > 0
    both = a & b
    relative = np.abs(blender["depth"][both] - ours["depth"][both]) / ours["depth"][both]
    return {"iou": float(both.sum() / (a | b).sum()), "median_depth_error": float(np.median(relative)),
            "p90_depth_error": float(np.percentile(relative, 90)),
            "part_agreement": float((blender["mask"][both] == ours["mask"][both]).mean()),
            "pixels": (int(a.sum()), int(b.sum()))}


def test_tree_masks_overlap(pairs):
    for index, (ours, blender) in enumerate(pairs):
        figures = _figures(ours, blender)
        print(f"view {index}: {figures}")
        assert figures["iou"] > MIN_IOU, figures


def test_depths_agree_on_the_shared_mask(pairs):
    for ours, blender in pairs:
        figures = _figures(ours, blender)
        assert figures["median_depth_error"] < MAX_MEDIAN_DEPTH_ERROR, figures


def test_bark_and_leaf_labels_agree(pairs):
    for ours, blender in pairs:
        figures = _figures(ours, blender)
        assert figures["part_agreement"] > MIN_PART_AGREEMENT, figures
