"""How alike two silhouettes are where a game would switch between them: the switch camera, closing, IoU.

In: a tree's points and a screen size in pixels of tree height; out: the `Camera` through which the tree shows
that size on a reference screen (`switch_camera`), coverage masks closed as a viewer sees a crown of sub-pixel
leaves (`closed_silhouette`) and their intersection over union (`silhouette_iou`), from the azimuths every LOD is
judged from (`QUALITY_AZIMUTHS`). The asset library's LOD and impostor checks, the reconstruction metrics and the
benchmarks compare silhouettes with these.
"""
from __future__ import annotations

import numpy as np

from .camera import TSN_FILL, Camera, perspective_camera
from .maps import closed_mask

__all__ = ["switch_camera", "closed_silhouette", "silhouette_iou", "SILHOUETTE_CLOSING_PX", "REFERENCE_SCREEN_PX",
           "REFERENCE_FOV_DEG", "QUALITY_AZIMUTHS"]

# Switch sizes are pixels of tree height on a reference screen this tall with this vertical field of view.
REFERENCE_SCREEN_PX = 1080
REFERENCE_FOV_DEG = 60.0
# Silhouettes are compared after closing gaps of about this radius (pixels at the switch size): leaves smaller
# than a pixel make a speckle whose exact pixels no simplification can (or should) reproduce.
SILHOUETTE_CLOSING_PX = 2
# Silhouettes are compared from these azimuths (degrees): 8 views 45 deg apart, each exactly between two of the
# crossed impostor's 8 planes (`renderers.impostor.IMPOSTOR_PLANES`: its worst case) and off every LOD card's axis.
QUALITY_AZIMUTHS = tuple(float(a) for a in np.arange(8) * 45.0 + 11.25)


def switch_camera(points: np.ndarray, azimuth_deg: float, screen_px: int) -> Camera:
    """The camera through which the tree (points (N, 3) metres) appears `screen_px` pixels tall (or wide, if
    wider) on the reference screen (REFERENCE_SCREEN_PX tall, REFERENCE_FOV_DEG vertical field of view): the
    crop of that screen around the tree, screen_px / 0.9 pixels square, perspective, elevation 0. Small trees
    on screen are far away, so their views come out nearly orthographic, as in a game."""
    size = int(np.ceil(screen_px / TSN_FILL))
    half_tan = np.tan(np.radians(REFERENCE_FOV_DEG) / 2) * size / REFERENCE_SCREEN_PX
    fov = float(np.degrees(2 * np.arctan(half_tan)))
    return perspective_camera(points, azimuth_deg, 0.0, size, fov_deg=fov,
                              name=f"az{azimuth_deg:05.1f}_{screen_px}px")


def closed_silhouette(coverage: np.ndarray, radius_px: int = SILHOUETTE_CLOSING_PX) -> np.ndarray:
    """(H, W) bool: a coverage mask with gaps narrower than about 2 radius_px pixels closed (`maps.closed_mask`):
    the outline a viewer sees of a crown of sub-pixel leaves."""
    return closed_mask(coverage, radius_px)


def silhouette_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (H, W) bool masks (1.0 when both are empty)."""
    union = np.logical_or(a, b).sum()
    return 1.0 if union == 0 else float(np.logical_and(a, b).sum() / union)
