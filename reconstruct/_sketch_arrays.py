"""Checks and conversions the sketch-reconstruction modules share: the error type, image and camera checks,
depth01 to metres, a pixel disc, a mask's runs of pixels (the photos' masks read them too)."""
from __future__ import annotations

import numpy as np

from renderers.camera import Camera
from species.errors import TreefarmError


class SketchError(TreefarmError):
    """Sketch-reconstruction input that cannot make a tree: blank maps, no trunk stroke, wrong shapes."""


def image_array(value, name: str, channels: tuple[int, ...]) -> np.ndarray:
    """`value` as an array of shape (H, W) (channels contains 0) or (H, W, C), C in channels."""
    array = np.asarray(value)
    if array.dtype == object or not (np.issubdtype(array.dtype, np.number) or array.dtype == bool):
        raise SketchError(f"{name} must be a numeric image array; got dtype {array.dtype}")
    if array.ndim == 3 and array.shape[2] == 1 and 0 in channels:
        array = array[..., 0]
    c = 0 if array.ndim == 2 else (array.shape[2] if array.ndim == 3 else -1)
    if c not in channels or min(array.shape[:2], default=0) < 8:
        want = " or ".join("(H, W)" if k == 0 else f"(H, W, {k})" for k in channels)
        raise SketchError(f"{name} has shape {array.shape}: allowed {want} with H, W >= 8")
    return array


def check_camera(camera, shape: tuple[int, int]) -> Camera:
    if not isinstance(camera, Camera):
        raise SketchError(f"camera must be a renderers.Camera; got {type(camera).__name__}")
    if (camera.height, camera.width) != tuple(shape):
        raise SketchError(f"maps of {shape[1]}x{shape[0]} px do not match the camera's "
                          f"{camera.width}x{camera.height} px: allowed maps of the camera's size")
    return camera


def check_height(height, default: str) -> None:
    """A SketchError unless `height` is None or a finite number of metres > 0; `default` names what None means."""
    if height is not None and not (isinstance(height, (int, float, np.number)) and np.isfinite(height)
                                   and height > 0):
        raise SketchError(f"height {height!r} must be a number of metres > 0 (or None for {default})")


def metres(camera: Camera, depth01: np.ndarray) -> np.ndarray:
    return camera.near + np.asarray(depth01, np.float64) * (camera.far - camera.near)


def disc(radius: float) -> np.ndarray:
    r = int(np.ceil(radius))
    y, x = np.mgrid[-r:r + 1, -r:r + 1]
    return x * x + y * y <= radius * radius


def mask_runs(mask: np.ndarray):
    """Horizontal runs of a bool mask: row (R,), first column (R,), length (R,), all int64, in row-major order,
    and the (H, W) int64 map of each stroke pixel's run length (0 off the strokes)."""
    h, w = mask.shape
    padded = np.zeros((h, w + 2), np.int8)
    padded[:, 1:-1] = mask
    step = np.diff(padded, axis=1)
    rows, first = np.nonzero(step == 1)
    _, end = np.nonzero(step == -1)
    length = end - first
    extent = np.zeros((h, w), np.int64)
    extent[mask] = np.repeat(length, length)  # runs cover the stroke pixels in row-major order
    return rows, first, length, extent
