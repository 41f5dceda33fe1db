"""Unit vectors: the one normalisation every generator, frame and field uses.

In: (..., 3) float arrays. Out: unit vectors of the same shape; vectors shorter than MIN_LENGTH come out zero, so a
direction that is undefined stays visibly undefined instead of blowing up.
"""
from __future__ import annotations

import numpy as np

__all__ = ["unit_vectors", "unit_vectors_and_lengths", "column_bounds", "MIN_LENGTH"]

# Shorter than this (metres, or a dimensionless cross product) a vector has no usable direction.
MIN_LENGTH = 1e-12


def unit_vectors_and_lengths(vectors: np.ndarray, min_length: float = MIN_LENGTH) -> tuple[np.ndarray, np.ndarray]:
    """(..., 3) unit vectors (zero where the length is <= min_length) and (...) lengths."""
    vectors = np.asarray(vectors)
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    unit = np.divide(vectors, length, out=np.zeros_like(vectors), where=length > min_length)
    return unit, length[..., 0]


def unit_vectors(vectors: np.ndarray, min_length: float = MIN_LENGTH) -> np.ndarray:
    """(..., 3) unit vectors; zero where a vector's length is <= min_length."""
    return unit_vectors_and_lengths(vectors, min_length)[0]


def column_bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(k,) min and (k,) max of each column of (N, k) `points`, in their dtype: the same values as
    `points.min(axis=0)`, reduced one column at a time because numpy's reduction across the rows of a C-ordered
    (N, 3) array is about 20x slower (measured: 10 ms against 0.5 ms for 376,516 float32 rows)."""
    columns = np.asarray(points).T
    return (np.array([column.min() for column in columns], columns.dtype),
            np.array([column.max() for column in columns], columns.dtype))
