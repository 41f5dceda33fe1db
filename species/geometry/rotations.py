"""Batched 3x3 rotations: axis rotations, Rodrigues, and the tracking frames Sapling orients stems with.

All functions take arrays of angles (radians) or vectors and return (N, 3, 3) float64 matrices whose columns are
the rotated x, y, z axes, so `R @ v` maps a local vector to world space.
"""
from __future__ import annotations

import numpy as np

from .vectors import row_norms

__all__ = ["rot_x", "rot_y", "rot_z", "rot_axis", "premul", "track_frames", "tilt_frames", "zxz", "declination", "apply",
           "euler_xyz", "from_euler_xyz", "unit_quaternions"]


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

    This is Blender's `Vector.to_track_quat('Z', 'Y')`, which Sapling uses to orient stems (the shortest rotation
    taking +z to the direction, then a roll of -atan2(-dx, -dy) about it). That frame works out to: y = world up
    projected off the direction, x = the horizontal normal (-dy, dx, 0) / |(dx, dy)|. Closed form, because it
    runs once per stem step and per leaf.
    """
    d = np.atleast_2d(np.asarray(directions, np.float64))
    d = d / np.maximum(row_norms(d)[:, None], 1e-300)
    dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
    s = np.hypot(dx, dy)
    vertical = s < 1e-12
    inv = 1.0 / np.where(vertical, 1.0, s)
    frames = np.empty((len(d), 3, 3))
    frames[:, 0, 0], frames[:, 1, 0], frames[:, 2, 0] = -dy * inv, dx * inv, 0.0
    frames[:, 0, 1], frames[:, 1, 1], frames[:, 2, 1] = -dz * dx * inv, -dz * dy * inv, s
    frames[:, :, 2] = d
    if vertical.any():  # Blender's choice for a stem straight up or down (a roll of pi)
        frames[vertical, :, 0] = (-1.0, 0.0, 0.0)
        frames[vertical, :, 1] = np.where(dz[vertical, None] > 0, (0.0, -1.0, 0.0), (0.0, 1.0, 0.0))
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
    Closed form of Ry(ry) @ Rx(-rx).
    """
    d = np.atleast_2d(np.asarray(directions, np.float64))
    d = d / np.maximum(row_norms(d)[:, None], 1e-300)
    ry = np.arctan2(d[:, 0], d[:, 2])
    rx = np.arctan2(d[:, 1], np.hypot(d[:, 0], d[:, 2]))
    cy, sy, cx, sx = np.cos(ry), np.sin(ry), np.cos(rx), np.sin(rx)
    frames = np.empty((len(d), 3, 3))
    frames[:, 0, 0], frames[:, 1, 0], frames[:, 2, 0] = cy, 0.0, -sy
    frames[:, 0, 1], frames[:, 1, 1], frames[:, 2, 1] = -sx * sy, cx, -sx * cy
    frames[:, :, 2] = d
    return frames


def zxz(alpha, beta, gamma) -> np.ndarray:
    """(N, 3, 3) = Rz(alpha) @ Rx(beta) @ Rz(gamma), in closed form."""
    ca, sa, cb, sb, cg, sg = (np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta), np.cos(gamma),
                              np.sin(gamma))
    ca, sa, cb, sb, cg, sg = np.broadcast_arrays(ca, sa, cb, sb, cg, sg)
    m = np.empty(ca.shape + (3, 3))
    m[..., 0, 0], m[..., 0, 1], m[..., 0, 2] = ca * cg - sa * cb * sg, -ca * sg - sa * cb * cg, sa * sb
    m[..., 1, 0], m[..., 1, 1], m[..., 1, 2] = sa * cg + ca * cb * sg, -sa * sg + ca * cb * cg, -ca * sb
    m[..., 2, 0], m[..., 2, 1], m[..., 2, 2] = sb * sg, sb * cg, cb
    return m


def declination(directions: np.ndarray) -> np.ndarray:
    """(N,) radians between each direction and world up."""
    d = np.atleast_2d(np.asarray(directions, np.float64))
    return np.arccos(np.clip(d[:, 2] / np.maximum(row_norms(d), 1e-300), -1, 1))


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
    """(N, 3, 3) = Rz(z) @ Ry(y) @ Rx(x), in closed form."""
    a = np.atleast_2d(angles)
    cx, sx, cy, sy, cz, sz = (np.cos(a[:, 0]), np.sin(a[:, 0]), np.cos(a[:, 1]), np.sin(a[:, 1]),
                              np.cos(a[:, 2]), np.sin(a[:, 2]))
    m = np.empty((len(a), 3, 3))
    m[:, 0, 0], m[:, 0, 1], m[:, 0, 2] = cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx
    m[:, 1, 0], m[:, 1, 1], m[:, 1, 2] = sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx
    m[:, 2, 0], m[:, 2, 1], m[:, 2, 2] = -sy, cy * sx, cy * cx
    return m


def unit_quaternions(rotations: np.ndarray) -> np.ndarray:
    """(N, 4) float64 unit quaternions (x, y, z, w), w >= 0 (one sign per rotation, so written bytes do not depend
    on scipy's choice), of proper rotation matrices (N, 3, 3). The matrices are taken as valid: scipy's default
    re-orthogonalises each by an SVD first, which costs far more than the conversion for a tree's leaf cards."""
    from scipy.spatial.transform import Rotation

    quat = Rotation.from_matrix(np.asarray(rotations, np.float64), assume_valid=True).as_quat()
    quat[quat[:, 3] < 0] *= -1.0
    return quat / np.linalg.norm(quat, axis=1, keepdims=True)
