"""Quaternions of rotation matrices: they rotate vectors as the matrices do, with one sign per rotation."""
from __future__ import annotations

import numpy as np

from species.geometry import rot_axis, unit_quaternions


def _rotate(quat: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """v' = q v q*, written out for unit quaternions (x, y, z, w)."""
    axis, w = quat[:, :3], quat[:, 3:]
    return vectors + 2.0 * np.cross(axis, np.cross(axis, vectors) + w * vectors)


def test_quaternions_rotate_as_their_matrices_with_w_not_negative():
    rng = np.random.default_rng(3)
    axes = rng.normal(size=(500, 3))
    angles = rng.uniform(-np.pi, np.pi, 500)
    matrices = rot_axis(axes / np.linalg.norm(axes, axis=1, keepdims=True), angles)
    quat = unit_quaternions(matrices)
    assert quat.shape == (500, 4) and quat.dtype == np.float64
    np.testing.assert_allclose(np.linalg.norm(quat, axis=1), 1.0, atol=1e-12)
    assert (quat[:, 3] >= 0).all()
    vectors = rng.normal(size=(500, 3))
    np.testing.assert_allclose(_rotate(quat, vectors), np.einsum("nij,nj->ni", matrices, vectors), atol=1e-12)


def test_known_quarter_turn_and_identity():
    quat = unit_quaternions(np.stack([np.eye(3), rot_axis(np.array([[0.0, 0.0, 1.0]]), np.pi / 2)[0]]))
    np.testing.assert_allclose(quat, [[0, 0, 0, 1], [0, 0, np.sqrt(0.5), np.sqrt(0.5)]], atol=1e-12)
