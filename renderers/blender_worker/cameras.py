"""Our camera convention (OpenCV axes, K in pixels, Z-up world) converted to a Blender camera's settings.

Pure Python (no numpy, no bpy) so both the worker and the main environment's tests can import it.
"""
from __future__ import annotations

import math

__all__ = ["CameraConversionError", "blender_camera_settings", "rigid_inverse"]

# OpenCV camera axes (x right, y down, z forward) to Blender's (x right, y up, looking down -z).
OPENCV_TO_BLENDER = ((1.0, 0.0, 0.0, 0.0), (0.0, -1.0, 0.0, 0.0), (0.0, 0.0, -1.0, 0.0), (0.0, 0.0, 0.0, 1.0))
SENSOR_WIDTH_MM = 36.0  # arbitrary: Blender only uses lens / sensor width, which we fix from fx and the width


class CameraConversionError(ValueError):
    """A camera dictionary Blender cannot reproduce (skew, non-square pixels, a non-rigid pose)."""


def _matmul(a, b):
    return tuple(tuple(sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)) for i in range(4))


def rigid_inverse(world_to_camera) -> tuple:
    """(4, 4) nested tuples: the inverse of a rotation + translation, checked to be one (within 1e-6)."""
    R = [[float(world_to_camera[i][j]) for j in range(3)] for i in range(3)]
    t = [float(world_to_camera[i][3]) for i in range(3)]
    for i in range(3):
        for j in range(3):
            dot = sum(R[i][k] * R[j][k] for k in range(3))
            if abs(dot - (1.0 if i == j else 0.0)) > 1e-6:
                raise CameraConversionError(f"world_to_camera rotation {R} is not orthonormal")
    if [float(x) for x in world_to_camera[3]] != [0.0, 0.0, 0.0, 1.0]:
        raise CameraConversionError(f"world_to_camera last row {list(world_to_camera[3])} must be [0, 0, 0, 1]")
    Rt = [[R[j][i] for j in range(3)] for i in range(3)]
    pos = [-sum(Rt[i][k] * t[k] for k in range(3)) for i in range(3)]
    return tuple(tuple(Rt[i]) + (pos[i],) for i in range(3)) + ((0.0, 0.0, 0.0, 1.0),)


def blender_camera_settings(camera: dict) -> dict:
    """Blender camera settings reproducing a camera dictionary (`renderers.camera.Camera.to_dict()`).

    Returns matrix_world ((4, 4) nested tuples, camera-to-world in Blender axes), type "PERSP"/"ORTHO",
    lens and sensor_width (mm, perspective), ortho_scale (metres across the width, orthographic),
    shift_x and shift_y (fractions of the width, which Blender's horizontal sensor fit measures them in),
    resolution_x and resolution_y (pixels), clip_start and clip_end (metres).
    The principal point moves from OpenCV pixel centres (j) to Blender's pixel corners (j + 0.5).
    """
    W, H = int(camera["width"]), int(camera["height"])
    K = [[float(x) for x in row] for row in camera["K"]]
    fx, fy, cx, cy = K[0][0], K[1][1], K[0][2], K[1][2]
    if abs(K[0][1]) > 1e-9:
        raise CameraConversionError(f"K skew {K[0][1]} must be 0: Blender cameras have no skew")
    if not (fx > 0 and fy > 0) or abs(fx - fy) > 1e-6 * fx:
        raise CameraConversionError(f"K focal lengths fx={fx}, fy={fy} must be equal and > 0 (square pixels)")
    projection = camera.get("projection", "perspective")
    if projection not in ("perspective", "orthographic"):
        raise CameraConversionError(f"projection {projection!r} is unknown: allowed 'perspective', 'orthographic'")
    pose = _matmul(rigid_inverse(camera["world_to_camera"]), OPENCV_TO_BLENDER)
    settings = {
        "matrix_world": pose,
        "resolution_x": W, "resolution_y": H,
        "shift_x": (W / 2 - (cx + 0.5)) / W,
        "shift_y": ((cy + 0.5) - H / 2) / W,
        "clip_start": float(camera.get("near", 0.1)), "clip_end": float(camera.get("far", 100.0)),
        "sensor_width": SENSOR_WIDTH_MM,
    }
    if projection == "orthographic":
        settings.update(type="ORTHO", ortho_scale=W / fx, lens=50.0)
    else:
        settings.update(type="PERSP", lens=fx * SENSOR_WIDTH_MM / W, ortho_scale=1.0)
    if not all(math.isfinite(v) for k, v in settings.items() if isinstance(v, float)):
        raise CameraConversionError(f"camera {camera.get('name', '?')} gives non-finite Blender settings")
    return settings
