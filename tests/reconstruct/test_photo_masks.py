"""Classical tree masks (issue 51) on the shared Blender photos: how much of the renderer's own tree mask they
find, deterministically, from the cameras' box round the tree, its base and points on it."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from reconstruct.metrics import silhouette_iou
from reconstruct.photo_masks import BASE_MARGIN, TreeWindow, mask_network, photo_mask, tree_mask, tree_window
from reconstruct.scoring import crowns
from reconstruct.visual_hull import PinholeView

ROOT = Path(__file__).resolve().parents[2]

# What the classical masks reach on the leafless orbit (pixels pooled over the ten photos; the crown's outline with
# the branches' gaps closed): floors a little under the measured values, so a change that loses the tree fails.
MIN_PIXEL_IOU = 0.45
MIN_CROWN_IOU = 0.65
# The tree mask network's on the same photos (Cycles renders it never trained on: textured ground, cast shadows).
NETWORK_PIXEL_IOU = 0.4
NETWORK_CROWN_IOU = 0.68


@pytest.fixture(scope="module")
def masked(photos, photo_tree):
    _, mesh = photo_tree
    bark = mesh.bark.vertices.astype(np.float64)
    lo, hi = bark.min(axis=0), bark.max(axis=0)
    bounds = np.array([lo - 0.1 * (hi - lo), hi + 0.1 * (hi - lo)])
    bounds[0, 2] = 0.0
    points = bark[:: max(1, len(bark) // 400)]       # standing in for SfM's points on the tree
    ours, truth, network = [], [], []
    net = mask_network()
    for camera, photo, mask in zip(photos.cameras, photos.images, photos.masks):
        view = PinholeView.from_camera(camera)
        image = np.asarray(Image.open(photo))
        window = tree_window(view, bounds, np.array([0.0, 0.0, 0.0]), points)
        ours.append(tree_mask(image, window))
        network.append(photo_mask(image, window, net))
        truth.append(np.asarray(Image.open(mask)) > 0)
    return np.stack(ours), np.stack(truth), image, np.stack(network)


def test_masks_find_the_tree_in_the_renders(masked):
    ours, truth, _, _ = masked
    assert silhouette_iou(ours, truth) >= MIN_PIXEL_IOU
    assert silhouette_iou(crowns(ours), crowns(truth)) >= MIN_CROWN_IOU


def test_masks_are_deterministic_and_empty_without_a_box(masked):
    _, _, image, _ = masked
    window = TreeWindow((40, 20, 280, 300), 250.0, np.array([[160, 200], [150, 120]]))
    assert np.array_equal(tree_mask(image, window), tree_mask(image, window))
    assert not tree_mask(image, TreeWindow((400, 0, 500, 10), None, np.zeros((0, 2), int))).any()


def test_the_network_masks_find_the_tree_in_the_renders(masked):
    _, truth, _, network = masked
    assert silhouette_iou(network, truth) >= NETWORK_PIXEL_IOU
    assert silhouette_iou(crowns(network), crowns(truth)) >= NETWORK_CROWN_IOU


def test_the_network_leaves_the_ground_below_the_base_to_the_background(masked):
    # the network takes the tree's cast shadow on the ground for the tree; the ground below the base row is not it
    _, truth, image, _ = masked
    net = mask_network()
    height, width = image.shape[:2]
    box = (0, 0, width, height)
    base = float(np.flatnonzero(truth[-1].any(axis=1)).max())       # the trunk's foot in the last photo
    free = net.mask(image, TreeWindow(box, None, np.zeros((0, 2), int)))
    cut = net.mask(image, TreeWindow(box, base, np.zeros((0, 2), int)))
    below = int(np.ceil(base + BASE_MARGIN * height))
    assert free[below:].any() and not cut[below:].any()
    assert np.array_equal(cut[:below], free[:below])


def test_an_unknown_mask_model_is_one_line_before_sfm(tmp_path):
    folder = tmp_path / "photos"
    folder.mkdir()
    for k in range(3):
        Image.fromarray(np.full((64, 64, 3), 40 * k, np.uint8)).save(folder / f"p{k}.png")
    out = tmp_path / "tree.glb"
    for extra, said in ((["--models", str(tmp_path / "no-registry")], "no-registry"),
                        (["--models", str(ROOT / "models" / "pix2pix-trunk")], "not tree-mask")):
        run = subprocess.run([sys.executable, "-m", "farm.cli", "reconstruct", str(folder), "--method", "photos",
                              "--height", "5", "--out", str(out), *extra], cwd=tmp_path, capture_output=True,
                             text=True, timeout=120)
        lines = [line for line in run.stderr.splitlines() if line.strip()]
        assert run.returncode == 2 and len(lines) == 1 and said in lines[0], run.stderr
        assert not out.exists() and not out.with_suffix(".sfm.log").exists()
