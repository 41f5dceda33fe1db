"""Photo-like colour views of a tree for the tree mask network (issue 51): the tree shaded under a random light in
jittered bark and leaf colours, over a procedural outdoor backdrop (sky, ground, far trees, buildings, poles,
fences, people), with a random exposure, colour cast, blur and sensor noise.

In: a view's part labels (1 bark, 2 leaves, 0 background), its normals, the tree's base colours and the view's
rng; out: (H, W, 3) uint8 sRGB. Everything random is drawn from the rng given, in a fixed order, so the same view
and rng give the same bytes. Nothing is downloaded: the backdrop is gradients, value noise and shapes, varied
enough that a network trained on it meets sky, grass, roads, fences and clutter in real photos.
"""
from __future__ import annotations

import cv2
import numpy as np

from species.meshing.textures import linear_to_srgb

__all__ = ["photo_view", "backdrop", "value_noise"]

# Linear RGB palettes the backdrop draws from (a colour is then jittered): skies top and bottom, grounds, clutter.
_SKIES = (((0.10, 0.25, 0.75), (0.55, 0.70, 0.90)),   # clear blue
          ((0.55, 0.58, 0.62), (0.80, 0.82, 0.85)),   # overcast
          ((0.80, 0.82, 0.85), (0.95, 0.95, 0.95)),   # white, blown-out
          ((0.20, 0.25, 0.50), (0.90, 0.55, 0.30)))   # dusk
_GROUNDS = ((0.10, 0.25, 0.05), (0.30, 0.30, 0.10), (0.25, 0.17, 0.09), (0.15, 0.15, 0.16), (0.45, 0.42, 0.35))
_FAR_TREES = ((0.05, 0.12, 0.04), (0.10, 0.18, 0.10), (0.20, 0.25, 0.22))
_BUILDINGS = ((0.50, 0.45, 0.40), (0.35, 0.15, 0.10), (0.60, 0.60, 0.62), (0.20, 0.20, 0.22))
_GARMENTS = ((0.60, 0.05, 0.05), (0.05, 0.10, 0.40), (0.05, 0.05, 0.05), (0.80, 0.80, 0.75), (0.60, 0.45, 0.10))
MAX_CLUTTER = 7           # shapes on the backdrop at most


def value_noise(rng: np.random.Generator, height: int, width: int, cells: int) -> np.ndarray:
    """(H, W) float32 smooth noise in about [-1, 1]: a `cells`-wide grid of uniform draws, upsampled cubically."""
    grid = rng.uniform(-1.0, 1.0, (max(2, cells * height // max(width, 1)), max(2, cells))).astype(np.float32)
    return cv2.resize(grid, (width, height), interpolation=cv2.INTER_CUBIC)


def _jitter(rng: np.random.Generator, colour, spread: float) -> np.ndarray:
    return np.clip(np.asarray(colour, np.float32) * rng.uniform(1 - spread, 1 + spread, 3), 0.0, 1.0)


def _pick(rng: np.random.Generator, palette) -> np.ndarray:
    return np.asarray(palette[int(rng.integers(len(palette)))], np.float32)


def backdrop(rng: np.random.Generator, height: int, width: int) -> np.ndarray:
    """(H, W, 3) float32 linear RGB: a sky gradient with clouds above a textured ground, then clutter."""
    rows = np.linspace(0.0, 1.0, height, dtype=np.float32)[:, None, None]
    top, bottom = (_jitter(rng, c, 0.2) for c in _SKIES[int(rng.integers(len(_SKIES)))])
    image = np.broadcast_to(top * (1 - rows) + bottom * rows, (height, width, 3)).copy()
    clouds = np.clip(value_noise(rng, height, width, int(rng.integers(3, 9))) * rng.uniform(0, 1.5), 0, 1)
    image += clouds[..., None] * (0.9 - image)
    horizon = int(rng.uniform(0.3, 1.1) * height)        # beyond the bottom: a photo looking up, no ground
    ground = _jitter(rng, _pick(rng, _GROUNDS), 0.3)
    texture = (value_noise(rng, height, width, int(rng.integers(8, 40))) * rng.uniform(0.1, 0.4)
               + value_noise(rng, height, width, 4) * 0.2)
    below = rows[..., 0] >= horizon / max(height, 1)
    land = ground * (1 + texture[..., None])
    if rng.random() < 0.4:                               # a road or path across the ground
        road = _jitter(rng, (0.18, 0.18, 0.19), 0.3)
        r0 = rng.uniform(min(horizon, height), height + 1)
        r1 = r0 + rng.uniform(0.05, 0.3) * height
        band = (np.arange(height)[:, None] >= r0) & (np.arange(height)[:, None] < r1)
        land = np.where(band[..., None], road * (1 + 0.3 * texture[..., None]), land)
    image = np.where(below[..., None], land, image)
    for _ in range(int(rng.integers(0, MAX_CLUTTER + 1))):
        _clutter(rng, image, horizon)
    return np.clip(image, 0.0, 1.0)


def _clutter(rng: np.random.Generator, image: np.ndarray, horizon: int) -> None:
    """One shape drawn in place: a far tree, a building, a pole, a fence or a person, standing near the horizon."""
    height, width = image.shape[:2]
    kind = int(rng.integers(5))
    x = int(rng.uniform(0, width))
    foot = int(np.clip(horizon + rng.uniform(-0.05, 0.4) * height, 0, height))
    layer = np.zeros((height, width), np.uint8)
    if kind == 0:                                        # a far tree or hedge: a lumpy dark blob
        rx, ry = (int(rng.uniform(0.05, 0.3) * width), int(rng.uniform(0.05, 0.25) * height))
        cv2.ellipse(layer, (x, foot - ry), (max(rx, 1), max(ry, 1)), 0, 0, 360, 1, -1)
        lumps = value_noise(rng, height, width, 16) > rng.uniform(-0.3, 0.3)
        shape = (cv2.dilate(layer, np.ones((5, 5), np.uint8)) > 0) & (lumps | (layer > 0))
        colour = _jitter(rng, _pick(rng, _FAR_TREES), 0.3)
    elif kind == 1:                                      # a building
        w, h = int(rng.uniform(0.1, 0.5) * width), int(rng.uniform(0.1, 0.5) * height)
        cv2.rectangle(layer, (x, foot - h), (x + w, foot), 1, -1)
        shape, colour = layer > 0, _jitter(rng, _pick(rng, _BUILDINGS), 0.3)
    elif kind == 2:                                      # a pole or post
        w = max(1, int(rng.uniform(0.005, 0.03) * width))
        cv2.rectangle(layer, (x, foot - int(rng.uniform(0.2, 0.8) * height)), (x + w, foot), 1, -1)
        shape, colour = layer > 0, _jitter(rng, (0.3, 0.3, 0.3), 0.6)
    elif kind == 3:                                      # a fence: posts and two rails
        w = int(rng.uniform(0.2, 0.8) * width)
        h = int(rng.uniform(0.04, 0.12) * height)
        thick = max(1, height // 100)
        for rail in (foot - h, foot - h // 2):
            cv2.line(layer, (x - w // 2, rail), (x + w // 2, rail), 1, thick)
        for post in range(x - w // 2, x + w // 2, max(4, w // 8)):
            cv2.line(layer, (post, foot - h - thick), (post, foot), 1, thick)
        shape, colour = layer > 0, _jitter(rng, (0.4, 0.32, 0.22), 0.5)
    else:                                                # a person: body and head
        h = max(4, int(rng.uniform(0.08, 0.35) * height))
        cv2.ellipse(layer, (x, foot - h // 3), (max(1, h // 8), h // 3), 0, 0, 360, 1, -1)
        cv2.circle(layer, (x, foot - 3 * h // 4), max(1, h // 10), 1, -1)
        shape, colour = layer > 0, _jitter(rng, _pick(rng, _GARMENTS), 0.3)
    image[shape] = colour * (1 + 0.1 * rng.standard_normal((int(shape.sum()), 1))).astype(np.float32)


def photo_view(rng: np.random.Generator, labels: np.ndarray, normals: np.ndarray, bark_color, leaf_color
               ) -> np.ndarray:
    """(H, W, 3) uint8 sRGB: the tree (`labels` 1 bark, 2 leaves; `normals` (H, W, 3) uint8 as the "normals"
    output stores them) shaded under a random light in jittered colours, composited over `backdrop`, then
    exposure, a colour cast, blur and noise. The tree covers exactly the pixels `labels` marks."""
    height, width = labels.shape
    image = backdrop(rng, height, width)
    light = np.array([rng.uniform(-1, 1), rng.uniform(-1, 0.1), rng.uniform(-1, 0.3)], np.float32)
    light /= np.linalg.norm(light) + 1e-9
    ambient = rng.uniform(0.2, 0.6)
    bark = _jitter(rng, bark_color, 0.4)
    leaves = _jitter(rng, leaf_color, 0.35)
    if rng.random() < 0.2:                               # autumn: yellow to red leaves
        leaves = _jitter(rng, (0.55, rng.uniform(0.15, 0.45), 0.05), 0.2)
    leaf_texture = 1 + value_noise(rng, height, width, int(rng.integers(10, 60))) * rng.uniform(0.1, 0.5)
    covered = labels > 0
    n = normals[covered].astype(np.float32) / 127.5 - 1.0
    shade = np.clip(-(n @ light), 0.0, 1.0) * (1 - ambient) + ambient
    albedo = np.where((labels[covered] == 1)[:, None], bark, leaves * leaf_texture[covered][:, None])
    image[covered] = np.clip(albedo * shade[:, None], 0.0, 1.0)
    image *= rng.uniform(0.6, 1.5) * _jitter(rng, (1.0, 1.0, 1.0), 0.1)
    sigma = rng.uniform(0.0, 1.0)
    if sigma > 0.3:
        image = cv2.GaussianBlur(image, (0, 0), sigma)
    image += rng.standard_normal(image.shape).astype(np.float32) * rng.uniform(0.0, 0.03)
    return np.round(linear_to_srgb(np.clip(image, 0.0, 1.0)) * 255).astype(np.uint8)
