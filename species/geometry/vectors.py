"""Unit vectors: the one normalisation every generator, frame and field uses.

In: (..., 3) float arrays. Out: unit vectors of the same shape; vectors shorter than MIN_LENGTH come out zero, so a
direction that is undefined stays visibly undefined instead of blowing up.
"""
from __future__ import annotations

import numpy as np

__all__ = ["unit_vectors", "unit_vectors_and_lengths", "row_norms", "cross_rows", "column_bounds", "row_bounds",
           "dot3", "MIN_LENGTH"]

# Shorter than this (metres, or a dimensionless cross product) a vector has no usable direction.
MIN_LENGTH = 1e-12


def row_norms(vectors: np.ndarray) -> np.ndarray:
    """(...) Euclidean lengths of (..., 3) vectors: the same values as `np.linalg.norm(vectors, axis=-1)` (the
    squares summed in the same order), without its per-call overhead, which dominates for the small arrays of a
    growth step."""
    v = np.asarray(vectors)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return np.sqrt(x * x + y * y + z * z)


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3) cross products a x b of (..., 3) vectors: `np.cross`'s values (the same products and differences),
    without its generic axis handling."""
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def unit_vectors_and_lengths(vectors: np.ndarray, min_length: float = MIN_LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """(..., 3) unit vectors (zero where the length is <= min_length) and (...) lengths."""
    vectors = np.asarray(vectors)
    length = row_norms(vectors)[..., None]
    unit = np.divide(vectors, length, out=np.zeros_like(vectors), where=length > min_length)
    return unit, length[..., 0]


def unit_vectors(vectors: np.ndarray, min_length: float = MIN_LENGTH) -> np.ndarray:
    """(..., 3) unit vectors; zero where a vector's length is <= min_length."""
    return unit_vectors_and_lengths(vectors, min_length)[0]


def column_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k,) min and (k,) max of each column of (N, k) `points`, in their dtype: the same values as
    `points.min(axis=0)`, reduced one column at a time because numpy's reduction across the rows of a C-ordered
    (N, 3) array is many times slower."""
    columns = np.asarray(points).T
    return (np.array([column.min() for column in columns], columns.dtype),
            np.array([column.max() for column in columns], columns.dtype))


def row_bounds(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N,) min and (N,) max of each row of (N, k) `values` (k small: a triangle's corners): the same values as
    `values.min(axis=1)`, taken as k - 1 elementwise minima of columns, because numpy's reduction along a short
    last axis is many times slower."""
    columns = np.asarray(values).T
    low, high = columns[0], columns[0]
    for column in columns[1:]:
        low, high = np.minimum(low, column), np.maximum(high, column)
    return low, high


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products along the last axis (length 3) of `a` and `b`, broadcast against each other: what
    `np.einsum("...k,...k->...", a, b)` gives, bit for bit (it sums a contraction of 3 contiguous values as
    (a0 b0 + a2 b2) + a1 b1; checked on the farm's arrays), and several times faster for the (F, 3, 3) corner
    arrays of twig cards, whose einsum paths numpy does not optimise."""
    a, b = np.asarray(a), np.asarray(b)
    return (a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2]) + a[..., 1] * b[..., 1]
