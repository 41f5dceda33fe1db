"""Tree masks of photos (issue 51): which pixels show the tree, by the tree mask network or, classically, from
colour, the sky and where the tree stands.

`MASKS` names the two ways: "network" (the default) runs the tree mask network (`trainers` task "tree-mask", the
shipped default in models/ or a registry's champion) with ONNX Runtime on the photo shrunk to NETWORK_SIDE px on
its longer side, its probabilities brought back to the photo's size; the tree is its pixels at 0.5 or above inside
the tree's box (other trees behind are not this one) and above the ground below its base row (the network takes
the tree's cast shadow on the ground for the tree). "classical" needs no network (what follows).

In: a photo (H, W, 3) uint8 and what the cameras already say about the tree in it (`TreeWindow`): the box the
tree's volume projects to, the image row of its base on the ground, and pixels SfM placed on the tree. Out: an
(H, W) bool mask.

The pixels surely not the tree are the sky (bright, unsaturated or blue, joined to the image's top), everything
outside the box and the ground below the base row. Their colours make the background's colour histogram, the
pixels at the tree's SfM points (with the box's strongly green pixels, leaves) the tree's; a pixel in the box is
the tree's when its colour is likelier under the tree's histogram. Small specks go and the small holes the
branches leave in a crown are closed. Deterministic: no random draw.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

from .networks import predictor
from .photo_folder import PhotoError
from .visual_hull import PinholeView

__all__ = ["TreeWindow", "tree_window", "tree_mask", "sky_mask", "BINS", "MASKS", "MASK_TASK", "NETWORK_SIDE",
           "MaskNetwork", "mask_network", "photo_mask"]

MASKS = ("network", "classical")
MASK_TASK = "tree-mask"   # the trainers task whose model draws the network masks
NETWORK_SIDE = 192        # px: the network sees a photo at this size on its longer side
_MULTIPLE = 8             # the network's height and width are multiples of this

BINS = 16                 # histogram bins per colour channel
HISTOGRAM_SIGMA = 1.0     # bins: colours next to a seen one count as seen
SKY_VALUE = 0.7           # sky: brighter than this (max channel, 0..1) and
SKY_SATURATION = 0.25     # less saturated than this, or blue above the other two
EXCESS_GREEN = 0.12       # 2g - r - b (0..1 channels) above this: vegetation
SPECK_SHARE = 2e-4        # components smaller than this share of the photo (and seedless) are dropped
HOLE_SHARE = 5e-4         # holes smaller than this share of the photo are filled
BASE_MARGIN = 0.02        # of the photo's height: the ground is sure only this far below the base row
TREE_ODDS = 2.0          # a pixel is the tree's when its colour is this many times likelier under the tree's histogram


@dataclass(frozen=True)
class TreeWindow:
    """Where the tree is in one photo: box (u0, v0, u1, v1) pixels (the tree's volume projected, clipped to the
    photo), base_row the image row of its base on the ground (None: unknown), seeds (K, 2) int (u, v) pixels
    of points on the tree (SfM's), possibly none."""

    box: tuple[int, int, int, int]
    base_row: float | None
    seeds: np.ndarray


def tree_window(view: PinholeView, bounds: np.ndarray, base: np.ndarray, points: np.ndarray) -> TreeWindow:
    """The tree's `TreeWindow` in `view`: bounds (2, 3) the box round its volume, base (3,) its base on the
    ground, points (K, 3) on it, all in the view's world."""
    corners = np.array([[x, y, z] for x in bounds[:, 0] for y in bounds[:, 1] for z in bounds[:, 2]])
    uv, depth = view.project(corners)
    width, height = view.size
    if (depth <= 0).any():
        box = (0, 0, width, height)     # the camera stands inside the box: anywhere may be the tree
    else:
        box = (int(np.floor(uv[:, 0].min())), int(np.floor(uv[:, 1].min())), int(np.ceil(uv[:, 0].max())) + 1,
               int(np.ceil(uv[:, 1].max())) + 1)
    base_uv, base_depth = view.project(np.asarray(base, np.float64).reshape(1, 3))
    seeds_uv, seeds_depth = view.project(np.asarray(points, np.float64).reshape(-1, 3))
    return TreeWindow(box, float(base_uv[0, 1]) if base_depth[0] > 0 else None,
                      np.floor(seeds_uv[seeds_depth > 0]).astype(np.int64))


def sky_mask(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: bright unsaturated or blue pixels joined to the photo's top row."""
    rgb = image[..., :3].astype(np.float64) / 255.0
    value, low = rgb.max(axis=2), rgb.min(axis=2)
    saturation = np.where(value > 0, (value - low) / np.maximum(value, 1e-9), 0.0)
    blue = (rgb[..., 2] > rgb[..., 0] + 0.04) & (rgb[..., 2] > rgb[..., 1]) & (value > 0.4)
    candidate = ((value > SKY_VALUE) & (saturation < SKY_SATURATION)) | blue
    labels, _ = ndimage.label(candidate)
    top = np.unique(labels[0][labels[0] > 0])
    return np.isin(labels, top)


def _histogram(codes: np.ndarray) -> np.ndarray:
    counts = np.bincount(codes, minlength=BINS ** 3).astype(np.float64).reshape(BINS, BINS, BINS)
    counts = ndimage.gaussian_filter(counts, HISTOGRAM_SIGMA, mode="constant")
    return (counts + 1e-3) / (counts.sum() + 1e-3 * counts.size)


def tree_mask(image: np.ndarray, window: TreeWindow) -> np.ndarray:
    """(H, W) bool: the tree's pixels in `image` (see the module docstring); all False when the box is empty."""
    image = np.asarray(image)[..., :3].astype(np.uint8)
    height, width = image.shape[:2]
    u0, v0, u1, v1 = (int(v) for v in window.box)
    u0, u1 = max(u0, 0), min(u1, width)
    v0, v1 = max(v0, 0), min(v1, height)
    mask = np.zeros((height, width), bool)
    if u1 <= u0 or v1 <= v0:
        return mask
    inside = np.zeros((height, width), bool)
    inside[v0:v1, u0:u1] = True
    sky = sky_mask(image)
    background = sky | ~inside
    if window.base_row is not None:
        background[int(np.clip(np.ceil(window.base_row + BASE_MARGIN * height), 0, height)):] = True
    quantised = image.astype(np.int64) * BINS // 256
    codes = (quantised[..., 0] * BINS + quantised[..., 1]) * BINS + quantised[..., 2]
    seeds = np.asarray(window.seeds, np.int64).reshape(-1, 2)
    seeds = seeds[(seeds[:, 0] >= 0) & (seeds[:, 0] < width) & (seeds[:, 1] >= 0) & (seeds[:, 1] < height)]
    tree_codes = codes[seeds[:, 1], seeds[:, 0]]
    if not len(tree_codes) or not background.any():
        return mask
    p_tree, p_background = _histogram(tree_codes), _histogram(codes[background])
    candidate = inside & ~sky & (p_tree[quantised[..., 0], quantised[..., 1], quantised[..., 2]]
                                 > TREE_ODDS * p_background[quantised[..., 0], quantised[..., 1], quantised[..., 2]])
    if window.base_row is not None:
        candidate[int(np.clip(np.ceil(window.base_row + BASE_MARGIN * height), 0, height)):] = False
    return _cleaned(candidate, seeds)


def _cleaned(candidate: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """Specks without a seed dropped, small holes filled."""
    area = candidate.size
    labels, count = ndimage.label(candidate, structure=np.ones((3, 3)))
    if count == 0:
        return candidate
    sizes = np.bincount(labels.ravel(), minlength=count + 1)
    keep = sizes >= SPECK_SHARE * area
    keep[np.unique(labels[seeds[:, 1], seeds[:, 0]])] = True
    keep[0] = False
    mask = keep[labels]
    holes, count = ndimage.label(~mask)
    sizes = np.bincount(holes.ravel(), minlength=count + 1)
    small = sizes < HOLE_SHARE * area
    small[0] = False
    return mask | small[holes]



class MaskNetwork:
    """The tree mask network of a loaded predictor (`trainers.models.Predictor` of task MASK_TASK)."""

    def __init__(self, net):
        if getattr(net, "task", None) != MASK_TASK:
            raise PhotoError(f"the model given for the masks is a {getattr(net, 'task', type(net).__name__)} "
                             f"model: allowed a {MASK_TASK} model")
        self.net = net

    def probabilities(self, image: np.ndarray, side: int = NETWORK_SIDE) -> np.ndarray:
        """(H, W) float32 in [0, 1]: the tree's probability at each pixel of `image` (H, W, 3) uint8, the network
        run on the photo shrunk to `side` px on its longer side (padded by reflection to its size multiple)."""
        image = np.asarray(image)[..., :3]
        height, width = image.shape[:2]
        scale = side / max(height, width)
        small = (max(1, round(width * scale)), max(1, round(height * scale)))
        shrunk = cv2.resize(image, small, interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
        pad_h, pad_w = (-small[1]) % _MULTIPLE, (-small[0]) % _MULTIPLE
        padded = np.pad(shrunk.reshape(small[1], small[0], 3), ((0, pad_h), (0, pad_w), (0, 0)), mode="reflect")
        out = self.net.model.run(np.moveaxis(padded, 2, 0)[None])[0, 0, :small[1], :small[0]]
        return cv2.resize(np.ascontiguousarray(out), (width, height), interpolation=cv2.INTER_LINEAR)

    def mask(self, image: np.ndarray, window: TreeWindow | None = None) -> np.ndarray:
        """(H, W) bool: the tree's pixels (probability 0.5 or above), inside `window`'s box and above the ground
        below its base row (as the classical masks' sure background) when one is given."""
        found = self.probabilities(image) >= 0.5
        if window is not None:
            u0, v0, u1, v1 = (int(v) for v in window.box)
            inside = np.zeros_like(found)
            inside[max(v0, 0):max(v1, 0), max(u0, 0):max(u1, 0)] = True
            found &= inside
            if window.base_row is not None:
                height = found.shape[0]
                found[int(np.clip(np.ceil(window.base_row + BASE_MARGIN * height), 0, height)):] = False
        return found


def mask_network(masks: str = "network", models=None, net=None) -> MaskNetwork | None:
    """The network that draws the masks, or None for "classical" ones. masks : one of MASKS. net : a predictor
    already loaded; else `models`: None for the shipped default, a model folder (holding model.json), or a
    registry (URI, folder or `Registry`: its champion). PhotoError (one line) for another `masks`; a missing or
    unreadable model raises the trainers' own one-line errors."""
    if masks not in MASKS:
        raise PhotoError(f"masks {masks!r} is not known: allowed {', '.join(MASKS)}")
    if masks == "classical":
        return None
    if net is None:
        if isinstance(models, (str, Path)) and (Path(models) / "model.json").is_file():
            from trainers.models import predictor_from_folder  # torch, ONNX Runtime: only where a network runs

            net = predictor_from_folder(models, MASK_TASK)
        else:
            net = predictor(MASK_TASK, models)
    return MaskNetwork(net)


def photo_mask(image: np.ndarray, window: TreeWindow, network: MaskNetwork | None) -> np.ndarray:
    """(H, W) bool: the tree's pixels in `image`, by `network` (inside the window's box) or, for None, classical."""
    if network is None:
        return tree_mask(image, window)
    return network.mask(image, window)
