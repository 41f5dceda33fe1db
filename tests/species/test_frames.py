"""Specification of species.geometry.frames: parallel-transport (rotation-minimizing) frames along polylines."""
import numpy as np
import pytest

from species.geometry.frames import FrameError, parallel_transport_frames, polyline_tangents, rotation_minimizing_frames


def _helix(n: int = 60, turns: float = 2.0) -> np.ndarray:
    t = np.linspace(0.0, 2 * np.pi * turns, n)
    return np.stack([np.cos(t), np.sin(t), 0.3 * t], axis=1)


def _sequential_transport(points: np.ndarray, first_normal: np.ndarray) -> np.ndarray:
    """Reference: the textbook per-step Rodrigues sweep (digest 3.8, Algorithm 9) on the same tangents."""
    tangents = polyline_tangents(points, np.array([0, len(points)]))
    normal = first_normal
    normals = [normal]
    for t0, t1 in zip(tangents[:-1], tangents[1:]):
        axis = np.cross(t0, t1)
        s, c = np.linalg.norm(axis), np.dot(t0, t1)
        if s > 1e-9:
            k = axis / s
            theta = np.arctan2(s, c)
            normal = (normal * np.cos(theta) + np.cross(k, normal) * np.sin(theta)
                      + k * np.dot(k, normal) * (1 - np.cos(theta)))
        normals.append(normal)
    return np.array(normals)


def test_frames_are_orthonormal_and_right_handed():
    t, n, b = rotation_minimizing_frames(_helix())
    for v in (t, n, b):
        np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,ij->i", t, n), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.cross(t, n), b, atol=1e-9)


def test_vectorized_frames_match_sequential_transport():
    points = _helix()
    _, normals, _ = rotation_minimizing_frames(points)
    np.testing.assert_allclose(normals, _sequential_transport(points, normals[0]), atol=1e-9)


def test_straight_line_keeps_a_constant_normal():
    points = np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2.5], [0, 0, 3]], float)
    _, normals, _ = rotation_minimizing_frames(points)
    np.testing.assert_allclose(normals, np.broadcast_to(normals[0], normals.shape), atol=1e-12)


def test_frames_do_not_twist_about_the_tangent():
    # Rotation-minimizing: the normal's change has no component along the binormal (no roll).
    t, n, b = rotation_minimizing_frames(_helix(400))
    dn = np.diff(n, axis=0)
    roll = np.abs(np.einsum("ij,ij->i", dn, b[:-1]))
    assert roll.max() < 0.01 * np.linalg.norm(dn, axis=1).max()


def test_batched_polylines_equal_each_one_alone():
    lines = [_helix(30), _helix(7, 0.5)[::-1] + 4.0, np.array([[0, 0, 0], [1.0, 0.0, 0.0]])]
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in lines])])
    _, normals, _ = parallel_transport_frames(np.concatenate(lines), offsets)
    for line, start, stop in zip(lines, offsets[:-1], offsets[1:]):
        np.testing.assert_allclose(normals[start:stop], rotation_minimizing_frames(line)[1], atol=1e-12)


def test_first_normal_is_perpendicular_to_world_y_unless_tangent_is_near_y():
    _, n, _ = rotation_minimizing_frames(np.array([[0, 0, 0], [0, 0, 1.0]]))
    assert abs(n[0, 1]) < 1e-12
    _, n, _ = rotation_minimizing_frames(np.array([[0, 0, 0], [0, 1.0, 0]]))
    assert abs(n[0, 0]) < 1e-12 and np.isfinite(n).all()


def test_tangent_at_a_corner_bisects_the_two_segments():
    t = polyline_tangents(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float), np.array([0, 3]))
    np.testing.assert_allclose(t[1], np.array([1, 1, 0]) / np.sqrt(2), atol=1e-12)


def test_repeated_points_are_rejected():
    with pytest.raises(FrameError, match="coincide"):
        rotation_minimizing_frames(np.array([[0, 0, 0], [0, 0, 0], [0, 0, 1.0]]))


def test_single_point_polyline_is_rejected():
    with pytest.raises(FrameError, match="at least 2"):
        parallel_transport_frames(np.zeros((3, 3)), np.array([0, 1, 3]))
