"""Batched 3x3 rotations: axis rotations, Rodrigues, and the tracking frames Sapling orients stems with.

All functions take arrays of angles (radians) or vectors and return (N, 3, 3) float64 matrices whose columns are
the rotated x, y, z axes, so `R @ v` maps a local vector to world space.
"""
from __future__ import annotations

import numpy as np

__all__ = ["rot_x", "rot_y", "rot_z", "rot_axis", "premul", "track_frames", "tilt_frames", "declination", "apply",
           "euler_xyz", "from_euler_xyz"]


def _batch(angle) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    a = np.atleast_1d(np.asarray(angle, np.float64))
    return a, np.cos(a), np.sin(a)


def rot_x(angle) -> np.ndarray:
    """(N, 3, 3) rotations about x by `angle` (N,) radians, right-handed."""
    a, c, s = _batch(angle)
    m = np.zeros((len(a), 3, 3))
    m[:, 0, 0] = 1
    m[:, 1, 1], m[:, 1, 2], m[:, 2, 1], m[:, 2, 2] = c, -s, s, c
    return m


def rot_y(angle) -> np.ndarray:
    a, c, s = _batch(angle)
    m = np.zeros((len(a), 3, 3))
    m[:, 1, 1] = 1
    m[:, 0, 0], m[:, 0, 2], m[:, 2, 0], m[:, 2, 2] = c, s, -s, c
    return m


def rot_z(angle) -> np.ndarray:
    a, c, s = _batch(angle)
    m = np.zeros((len(a), 3, 3))
    m[:, 2, 2] = 1
    m[:, 0, 0], m[:, 0, 1], m[:, 1, 0], m[:, 1, 1] = c, -s, s, c
    return m


def rot_axis(axis: np.ndarray, angle) -> np.ndarray:
    """(N, 3, 3) rotations about unit axes (N, 3) by angles (N,) radians (Rodrigues)."""
    k = np.atleast_2d(np.asarray(axis, np.float64))
    a, c, s = _batch(angle)
    kx, ky, kz = k[:, 0], k[:, 1], k[:, 2]
    cross = np.zeros((len(k), 3, 3))
    cross[:, 0, 1], cross[:, 0, 2] = -kz, ky
    cross[:, 1, 0], cross[:, 1, 2] = kz, -kx
    cross[:, 2, 0], cross[:, 2, 1] = -ky, kx
    outer = k[:, :, None] * k[:, None, :]
    eye = np.eye(3)[None]
    return c[:, None, None] * eye + s[:, None, None] * cross + (1 - c)[:, None, None] * outer


def apply(rotations: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """(N, 3): each rotation applied to its vector."""
    return np.einsum("nij,nj->ni", rotations, vectors)


def track_frames(directions: np.ndarray) -> np.ndarray:
    """(N, 3, 3) frames whose z axis is each direction and whose y axis leans toward world up.

    This is Blender's `Vector.to_track_quat('Z', 'Y')`, which Sapling uses to orient stems: the shortest
    rotation taking +z to the direction, followed by a roll about the direction of -atan2(-dx, -dy).
    Built in closed form (no batched matrix products): it runs once per stem step and per leaf.
    """
    d = np.atleast_2d(np.asarray(directions, np.float64))
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    down = dz < -1 + 1e-12  # the shortest arc is undefined: turn by pi about x, as Blender does
    k = 1.0 / np.where(down, 1.0, 1.0 + dz)
    x1 = np.stack([1 - dx * dx * k, -dx * dy * k, -dx], axis=1)
    y1 = np.stack([-dx * dy * k, 1 - dy * dy * k, -dy], axis=1)
    x1[down], y1[down] = (1.0, 0.0, 0.0), (0.0, -1.0, 0.0)
    vertical = (np.abs(dx) < 1e-12) & (np.abs(dy) < 1e-12) & (dz > 0)
    # atan2(-0.0, -0.0) is -pi in C; keep Blender's choice for exactly vertical stems.
    roll = np.where(vertical, np.pi, -np.arctan2(-dx, -dy))[:, None]
    c, s = np.cos(roll), np.sin(roll)
    frames = np.empty((len(d), 3, 3))
    frames[:, :, 0] = c * x1 + s * y1
    frames[:, :, 1] = c * y1 - s * x1
    frames[:, :, 2] = d
    return frames


def premul(axis: str, angle, matrices: np.ndarray) -> np.ndarray:
    """R_axis(angle) @ matrices, for (N, 3, 3) or (N, 3) inputs, by elementwise row mixing (no matmul)."""
    a = np.asarray(angle, np.float64)
    c, s = np.cos(a), np.sin(a)
    m = np.asarray(matrices, np.float64)
    if m.ndim == 3:
        c, s = np.reshape(c, (-1, 1)), np.reshape(s, (-1, 1))
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    out = m.copy()
    out[:, i] = c * m[:, i] - s * m[:, j]
    out[:, j] = s * m[:, i] + c * m[:, j]
    return out


def tilt_frames(directions: np.ndarray) -> np.ndarray:
    """(N, 3, 3) frames with z along each direction built as Euler XYZ (-rx, ry, 0): no roll about z.

    Sapling orients trunk segments this way, so trunk curvature bends in a fixed world plane.
    """
    d = np.atleast_2d(np.asarray(directions, np.float64))
    d = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    ry = np.arctan2(d[:, 0], d[:, 2])
    rx = np.arctan2(d[:, 1], np.hypot(d[:, 0], d[:, 2]))
    return rot_y(ry) @ rot_x(-rx)


def declination(directions: np.ndarray) -> np.ndarray:
    """(N,) radians between each direction and world up."""
    d = np.atleast_2d(np.asarray(directions, np.float64))
    return np.arccos(np.clip(d[:, 2] / np.maximum(np.linalg.norm(d, axis=1), 1e-300), -1, 1))


def euler_xyz(frames: np.ndarray, reference_z: np.ndarray) -> np.ndarray:
    """(N, 3) Euler XYZ angles (R = Rz Ry Rx) of each frame, picking of the two solutions the one whose
    z angle is closest to `reference_z` (N,) radians (Blender's `to_euler(..., compat)` behaviour)."""
    m = np.asarray(frames, np.float64)
    cy = np.hypot(m[:, 0, 0], m[:, 1, 0])
    x1 = np.arctan2(m[:, 2, 1], m[:, 2, 2])
    y1 = np.arctan2(-m[:, 2, 0], cy)
    z1 = np.arctan2(m[:, 1, 0], m[:, 0, 0])
    x2 = np.arctan2(-m[:, 2, 1], -m[:, 2, 2])
    y2 = np.arctan2(-m[:, 2, 0], -cy)
    z2 = np.arctan2(-m[:, 1, 0], -m[:, 0, 0])

    def dist(z):
        return np.abs(np.angle(np.exp(1j * (z - reference_z))))

    pick2 = dist(z2) < dist(z1)
    return np.stack([np.where(pick2, x2, x1), np.where(pick2, y2, y1), np.where(pick2, z2, z1)], axis=1)


def from_euler_xyz(angles: np.ndarray) -> np.ndarray:
    """(N, 3, 3) = Rz(z) @ Ry(y) @ Rx(x)."""
    a = np.atleast_2d(angles)
    return rot_z(a[:, 2]) @ rot_y(a[:, 1]) @ rot_x(a[:, 0])
