"""Rotation-minimizing frames along polylines by parallel transport, for many polylines at once.

In: points of concatenated polylines and their offsets. Out: unit tangents, normals and binormals per point.
"""
from __future__ import annotations

import numpy as np

from ..errors import TreefarmError
from .vectors import cross_rows, row_norms, unit_vectors

__all__ = ["FrameError", "polyline_tangents", "parallel_transport_frames", "rotation_minimizing_frames"]

# Below this (in units of length squared or of 1 + cos) a direction is treated as undefined.
_EPS = 1e-12


class FrameError(TreefarmError):
    """Polyline arrays that cannot carry frames (wrong shape, repeated points, bad offsets)."""


def _check_polylines(points: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    points = np.asarray(points, np.float64)
    offsets = np.asarray(offsets, np.int64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise FrameError(f"points must have shape (K, 3); got {points.shape}")
    if offsets.ndim != 1 or len(offsets) < 2 or offsets[0] != 0 or offsets[-1] != len(points):
        raise FrameError(f"offsets must run from 0 to len(points) = {len(points)}; got {offsets[:3]}..{offsets[-1:]}")
    sizes = np.diff(offsets)
    if np.any(sizes < 2):
        i = int(np.flatnonzero(sizes < 2)[0])
        raise FrameError(f"polyline {i} has {sizes[i]} points: every polyline needs at least 2")
    return points, offsets


def polyline_tangents(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Unit tangent at each point: the mean of its incoming and outgoing segment directions.

    points  : (K, 3) float, metres, the points of P polylines one after another.
    offsets : (P + 1,) int, polyline p owns points[offsets[p]:offsets[p + 1]] (at least 2 points each).
    Returns (K, 3) float64 unit vectors. End points take their one segment's direction; where the two
    directions cancel (a full reversal) the incoming one is used. Consecutive points must differ.
    """
    points, offsets = _check_polylines(points, offsets)
    seg = np.diff(points, axis=0)  # seg[k] joins point k to k + 1 (meaningless across polylines)
    seg_len = row_norms(seg)
    last = offsets[1:] - 1  # last point of each polyline: its outgoing "segment" crosses into the next
    inner_seg = np.ones(len(seg), bool)
    inner_seg[last[:-1]] = False
    if np.any(inner_seg & (seg_len * seg_len < _EPS)):
        k = int(np.flatnonzero(inner_seg & (seg_len * seg_len < _EPS))[0])
        raise FrameError(f"points {k} and {k + 1} coincide: merge repeated points before computing frames")
    direction = unit_vectors(seg)
    incoming = np.empty_like(points)
    outgoing = np.empty_like(points)
    incoming[1:] = direction
    outgoing[:-1] = direction
    first = offsets[:-1]
    incoming[first] = outgoing[first]
    outgoing[last] = incoming[last]
    summed = incoming + outgoing
    reversed_ = np.einsum("ij,ij->i", summed, summed) < 1e-8
    summed[reversed_] = incoming[reversed_]
    return unit_vectors(summed)


def _reference_normals(tangents: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each tangent: T x (0, 1, 0), or T x (1, 0, 0) near the Y axis."""
    ref = np.zeros_like(tangents)
    near_y = np.abs(tangents[:, 1]) > 0.9
    ref[~near_y, 1] = 1.0
    ref[near_y, 0] = 1.0
    return unit_vectors(cross_rows(tangents, ref))


def _transport(vectors: np.ndarray, t_from: np.ndarray, t_to: np.ndarray) -> np.ndarray:
    """Rotate each vector by the smallest rotation that takes unit t_from to unit t_to (Rodrigues form)."""
    axis = cross_rows(t_from, t_to)  # |axis| = sin of the angle
    cos = np.einsum("ij,ij->i", t_from, t_to)
    # R x = x + v x x + v x (v x x) / (1 + c); undefined for a full reversal, where we keep x.
    denom = 1.0 + cos
    ok = denom > 1e-9
    vxx = cross_rows(axis, vectors)
    rotated = vectors + vxx + cross_rows(axis, vxx) / np.where(ok, denom, 1.0)[:, None]
    return np.where(ok[:, None], rotated, vectors)


def parallel_transport_frames(points: np.ndarray, offsets: np.ndarray,
                              tangents: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation-minimizing (parallel-transport) frames along every polyline, in one vectorized pass.

    points   : (K, 3) float, metres, P polylines one after another.
    offsets  : (P + 1,) int, polyline p owns points[offsets[p]:offsets[p + 1]] (at least 2 points each).
    tangents : optional (K, 3) float unit tangents; default `polyline_tangents(points, offsets)`.
    Returns (tangents, normals, binormals), each (K, 3) float64 unit vectors with B = T x N.

    The first frame of each polyline has N = normalize(T x (0, 1, 0)) (or (1, 0, 0) when T is near Y);
    each next normal is the previous one rotated by the smallest rotation taking T_k to T_k+1. Instead of
    a sequential sweep, every point gets a cheap reference normal; transporting point k's reference to
    k + 1 differs from k + 1's reference by a twist angle about T_k+1, and because transport commutes
    with twists about the tangent, the frame at k is the reference twisted by the cumulative sum of
    those angles along the polyline. So the whole thing is a few array operations and one cumsum.
    """
    points, offsets = _check_polylines(points, offsets)
    if tangents is None:
        tangents = polyline_tangents(points, offsets)
    else:
        tangents = unit_vectors(np.asarray(tangents, np.float64))
        if tangents.shape != points.shape:
            raise FrameError(f"tangents must have shape {points.shape}; got {tangents.shape}")
    reference = _reference_normals(tangents)
    carried = _transport(reference[:-1], tangents[:-1], tangents[1:])  # reference k moved to k + 1
    # Signed angle from reference[k+1] to carried[k] about tangent[k+1].
    sin = np.einsum("ij,ij->i", tangents[1:], cross_rows(reference[1:], carried))
    cos = np.einsum("ij,ij->i", reference[1:], carried)
    step = np.zeros(len(points))
    step[1:] = np.arctan2(sin, cos)
    step[offsets[:-1]] = 0.0  # no twist carried across polylines
    twist = np.cumsum(step)
    twist -= np.repeat(twist[offsets[:-1]], np.diff(offsets))
    binormal_ref = cross_rows(tangents, reference)
    cos_t, sin_t = np.cos(twist)[:, None], np.sin(twist)[:, None]
    normals = cos_t * reference + sin_t * binormal_ref
    normals = unit_vectors(normals - tangents * np.einsum("ij,ij->i", normals, tangents)[:, None])
    binormals = cross_rows(tangents, normals)
    return tangents, normals, binormals


def rotation_minimizing_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frames along one polyline: `parallel_transport_frames` with a single polyline.

    points : (K, 3) float, metres, K >= 2 with no two consecutive points equal.
    Returns (tangents, normals, binormals), each (K, 3) float64.
    """
    points = np.asarray(points, np.float64)
    return parallel_transport_frames(points, np.array([0, len(points)]))
