"""Classical tree masks (issue 51) on the shared Blender photos: how much of the renderer's own tree mask they
find, deterministically, from the cameras' box round the tree, its base and points on it."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from reconstruct.metrics import silhouette_iou
from reconstruct.photo_masks import TreeWindow, tree_mask, tree_window
from reconstruct.scoring import crowns
from reconstruct.visual_hull import PinholeView

# What the classical masks reach on the leafless orbit (pixels pooled over the ten photos; the crown's outline with
# the branches' gaps closed): floors a little under the measured values, so a change that loses the tree fails.
MIN_PIXEL_IOU = 0.45
MIN_CROWN_IOU = 0.65


@pytest.fixture(scope="module")
def masked(photos, photo_tree):
    _, mesh = photo_tree
    bark = mesh.bark.vertices.astype(np.float64)
    lo, hi = bark.min(axis=0), bark.max(axis=0)
    bounds = np.array([lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)])
    bounds[0, 2] = 0.0
    points = bark[:: max(1, len(bark) // 400)]       # standing in for SfM's points on the tree
    ours, truth = [], []
    for camera, photo, mask in zip(photos.cameras, photos.images, photos.masks):
        view = PinholeView.from_camera(camera)
        image = np.asarray(Image.open(photo))
        ours.append(tree_mask(image, tree_window(view, bounds, np.array([0.0, 0.0, 0.0]), points)))
        truth.append(np.asarray(Image.open(mask)) > 0)
    return np.stack(ours), np.stack(truth), image


def test_masks_find_the_tree_in_the_renders(masked):
    ours, truth, _ = masked
    assert silhouette_iou(ours, truth) >= MIN_PIXEL_IOU
    assert silhouette_iou(crowns(ours), crowns(truth)) >= MIN_CROWN_IOU


def test_masks_are_deterministic_and_empty_without_a_box(masked):
    _, _, image = masked
    window = TreeWindow((40, 20, 280, 300), 250.0, np.array([[160, 200], [150, 120]]))
    assert np.array_equal(tree_mask(image, window), tree_mask(image, window))
    assert not tree_mask(image, TreeWindow((400, 0, 500, 10), None, np.zeros((0, 2), int))).any()
