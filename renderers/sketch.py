"""Sketch styles, black (0) lines on white (255), (H, W) uint8, from masks, depth, normals and the skeleton.

Styles: `tsn` (TreeSketchNet), `edges` (seed 000), `strokes` / `strokes_brush` / `crown` (seed 001), `hand` (ours).
"""
from __future__ import annotations

import cv2
import numpy as np

from species.skeleton import Skeleton

from .camera import Camera
from .strokes import branch_polylines, main_branches

__all__ = ["sketch_tsn", "sketch_edges", "edges_of_grey", "sketch_strokes", "sketch_strokes_brush", "crown_region",
           "sketch_crown", "sketch_hand", "shaded"]

SOBEL_STEP = 4.0        # 3x3 Sobel response to a 0 -> 1 step: the scale that maps an edge to 1
TSN_RAMP = 0.9          # digest 4.2: Sobel values below 0.9 become paper
TSN_SPECK_PX = 6        # edge blobs smaller than this many pixels are specks, not lines
CROWN_SIGMA_608 = 4.0   # digest 4.2: leaf blur sigma at 608 px, scaled with the image
CROWN_THRESHOLD = 0.01  # digest 4.2: blurred leaf values above 0.01 are crown


def _scale(size: int) -> float:
    """Line and blur sizes are set at 256 px and grow with the image."""
    return size / 256.0


def _sobel_edges(region: np.ndarray) -> np.ndarray:
    """(H, W) bool, pixels where the Sobel magnitude of a binary region reaches TSN_RAMP of a full step."""
    img = region.astype(np.float32)
    gx = cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3)
    return np.sqrt(gx * gx + gy * gy) >= TSN_RAMP * SOBEL_STEP


def _drop_specks(lines: np.ndarray, min_pixels: int) -> np.ndarray:
    count, labels, stats, _ = cv2.connectedComponentsWithStats(lines.astype(np.uint8), connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= min_pixels
    big[0] = False
    return big[labels]


def crown_region(leaf_mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: the crown as a closed region, the leaf mask (H, W) bool blurred (sigma 4 px at 608 px) and
    thresholded at 0.01."""
    sigma = max(1.5, CROWN_SIGMA_608 * leaf_mask.shape[0] / 608.0)
    blurred = cv2.GaussianBlur(leaf_mask.astype(np.float32), (0, 0), sigma)
    return blurred > CROWN_THRESHOLD


def sketch_tsn(bark_mask: np.ndarray, leaf_mask: np.ndarray) -> np.ndarray:
    """TreeSketchNet style (digest 4.2): bark drawn as the double contour of the bark mask (H, W) bool (all bark,
    leaves ignored) with sub-pixel twigs opened away, times the crown outline from the leaf mask (H, W) bool."""
    thick_bark = cv2.morphologyEx(bark_mask.astype(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8)) > 0
    bark_lines = _drop_specks(_sobel_edges(thick_bark), TSN_SPECK_PX)
    crown_lines = _sobel_edges(crown_region(leaf_mask)) if leaf_mask.any() else np.zeros_like(bark_lines)
    # bark image x leaf image, each white paper with black lines: the product is black where either has a line.
    return np.where(bark_lines | crown_lines, 0, 255).astype(np.uint8)


def shaded(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(H, W) uint8 grey Lambert shading of camera-frame normals (H, W, 3) uint8, light from the upper left and
    front; background (mask (H, W) == 0) white."""
    n = normals.astype(np.float32) / 127.5 - 1.0
    light = np.array([-0.45, -0.6, -0.66], np.float32)
    light /= np.linalg.norm(light)
    lambert = np.clip(n @ light, 0.0, 1.0)
    grey = 40.0 + 170.0 * lambert
    return np.where(mask > 0, grey, 255.0).astype(np.uint8)


def edges_of_grey(grey: np.ndarray) -> np.ndarray:
    """Seed 000's edge step (digest 1.8) on any (H, W) uint8 grey image, a render or a photo: Gaussian blur 5x5,
    sigma 1.4, then Canny 50/150; edges black on white."""
    edges = cv2.Canny(cv2.GaussianBlur(np.ascontiguousarray(grey, np.uint8), (5, 5), 1.4), 50, 150)
    return np.where(edges > 0, 0, 255).astype(np.uint8)


def sketch_edges(normals: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Seed 000's silhouette input: `edges_of_grey` of the shaded render of the visible tree."""
    return edges_of_grey(shaded(normals, mask))


def _projected_main_segments(camera: Camera, skeleton: Skeleton):
    """Pixels (S, 2) of segment starts and ends, start node ids, branch rank (S,) of the main branches."""
    a, b, k = branch_polylines(skeleton, main_branches(skeleton))
    pa, _ = camera.project(skeleton.positions[a])
    pb, _ = camera.project(skeleton.positions[b])
    return pa, pb, a, b, k


def _draw_segments(image: np.ndarray, pa: np.ndarray, pb: np.ndarray, thickness: np.ndarray,
                   line_type: int = cv2.LINE_8) -> None:
    """Draw segments (S, 2) pixels -> (S, 2) pixels in black, one cv2.polylines call per thickness."""
    shift = 4
    segs = np.round(np.stack([pa, pb], axis=1) * (1 << shift)).astype(np.int32)  # (S, 2, 2) sub-pixel
    for t in np.unique(thickness):
        chosen = segs[thickness == t]
        cv2.polylines(image, list(chosen), False, 0, int(t), line_type, shift)


def sketch_strokes(camera: Camera, skeleton: Skeleton) -> np.ndarray:
    """Seed 001's 1-pixel pen: the main branches as connected single-pixel (8-connected) polylines."""
    image = np.full((camera.height, camera.width), 255, np.uint8)
    pa, pb, *_ = _projected_main_segments(camera, skeleton)
    _draw_segments(image, pa, pb, np.ones(len(pa), np.int64))
    return image


def sketch_strokes_brush(camera: Camera, skeleton: Skeleton) -> np.ndarray:
    """Seed 001's brush: the main branches drawn with the branch diameter (at each segment's start) in pixels,
    at least 1 px."""
    image = np.full((camera.height, camera.width), 255, np.uint8)
    pa, pb, a, b, _ = _projected_main_segments(camera, skeleton)
    _, depth = camera.project(skeleton.positions[a])
    diameter_px = 2.0 * skeleton.radius[a] / camera.metres_per_pixel(np.maximum(depth, camera.near))
    thickness = np.clip(np.round(diameter_px), 1, camera.height // 4).astype(np.int64)
    _draw_segments(image, pa, pb, thickness)
    return image


def sketch_crown(region: np.ndarray) -> np.ndarray:
    """Seed 001's crown layer: the outer contour of the crown region (H, W) bool, lines 1 px per 256 px."""
    image = np.full(region.shape, 255, np.uint8)
    contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    thickness = max(1, round(_scale(region.shape[0])))
    cv2.drawContours(image, contours, -1, 0, thickness, cv2.LINE_8)
    return image


# ------------------------------------------------------------------------------------------------ hand
def _resample(points: np.ndarray, spacing: float) -> np.ndarray:
    """(P, 2) points along a polyline (N, 2) pixels, `spacing` apart (ends kept)."""
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    arc = np.concatenate(([0.0], np.cumsum(steps)))
    if arc[-1] <= 0:
        return points[:1]
    at = np.linspace(0.0, arc[-1], max(2, int(np.ceil(arc[-1] / spacing)) + 1))
    return np.stack([np.interp(at, arc, points[:, 0]), np.interp(at, arc, points[:, 1])], axis=1)


def _wobble(points: np.ndarray, amplitude: float, rng: np.random.Generator) -> np.ndarray:
    """Shift each point sideways by a smooth random offset (two sines of random wavelength and phase)."""
    if len(points) < 2:
        return points
    tangent = np.gradient(points, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), 1e-9)
    side = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    s = np.arange(len(points), dtype=np.float64)
    freq = rng.uniform(0.05, 0.25, 2)
    phase = rng.uniform(0, 2 * np.pi, 2)
    offset = amplitude * (0.7 * np.sin(freq[0] * s + phase[0]) + 0.3 * np.sin(freq[1] * s + phase[1]))
    return points + side * offset[:, None]


def _hand_stroke(points: np.ndarray, weight: float, scale: float, rng: np.random.Generator):
    """One pen stroke along a polyline (N, 2) pixels: resampled, wobbled, over-shot at the end, with pressure
    rising and falling and maybe one gap. Returns segment starts (S, 2), ends (S, 2) and thickness (S,) int."""
    pts = _resample(points, 3.0 * scale)
    if len(pts) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0, np.int64)
    end_dir = pts[-1] - pts[-2]
    end_dir /= max(np.linalg.norm(end_dir), 1e-9)
    overshoot = pts[-1] + end_dir * rng.uniform(1.0, 5.0) * scale
    pts = _wobble(np.concatenate([pts, overshoot[None]]), rng.uniform(0.4, 1.2) * scale, rng)
    t = np.linspace(0.0, 1.0, len(pts) - 1)
    pressure = np.sin(np.pi * np.clip(0.1 + 0.9 * t, 0, 1)) ** 0.5 * rng.uniform(0.7, 1.0)
    thickness = np.clip(np.round(weight * scale * (0.4 + pressure)), 1, None).astype(np.int64)
    keep = np.ones(len(pts) - 1, bool)
    if len(keep) > 6 and rng.random() < 0.35:  # the pen lifts for a moment
        start = int(rng.integers(2, len(keep) - 3))
        keep[start:start + int(rng.integers(1, 3))] = False
    return pts[:-1][keep], pts[1:][keep], thickness[keep]


def sketch_hand(camera: Camera, skeleton: Skeleton, region: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A drawn look (our style): main branches and the crown outline (region (H, W) bool) as wobbly pen strokes
    with varying pressure, small gaps and over-shoot (binary, like the other styles); the rng decides every wobble."""
    h, w = camera.height, camera.width
    scale = _scale(h)
    image = np.full((h, w), 255, np.uint8)
    branches = main_branches(skeleton)
    paths = skeleton.branch_paths
    starts, ends, widths = [], [], []
    for rank, branch in enumerate(branches):
        uv, _ = camera.project(skeleton.positions[paths[int(branch)]])
        weight = 2.6 if rank == 0 else 1.6 if skeleton.order[paths[int(branch)][-1]] <= 1 else 1.1
        a, b, t = _hand_stroke(uv, weight, scale, rng)
        starts.append(a)
        ends.append(b)
        widths.append(t)
    contours, _ = cv2.findContours(region.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    for contour in contours:
        outline = contour[:, 0, :].astype(np.float64)
        if len(outline) < 8:
            continue
        outline = np.concatenate([outline, outline[:1]])
        # Two or three strokes around the crown, each running a little past the next one's start.
        cuts = np.sort(rng.choice(np.arange(1, len(outline) - 1), int(rng.integers(1, 3)), replace=False))
        for piece in np.split(outline, cuts):
            a, b, t = _hand_stroke(piece, 1.2, scale, rng)
            starts.append(a)
            ends.append(b)
            widths.append(t)
    if starts:
        _draw_segments(image, np.concatenate(starts), np.concatenate(ends), np.concatenate(widths))
    return image
