"""The shared vector kernels of species/geometry/vectors.py: unit vectors, per-column and per-row bounds, dot
products of 3-vectors."""
import numpy as np
import pytest

from species.geometry.vectors import MIN_LENGTH, column_bounds, dot3, row_bounds, unit_vectors_and_lengths


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int64])
def test_column_bounds_are_numpys_per_axis_min_and_max_in_the_same_dtype(dtype):
    points = np.random.default_rng(0).normal(0, 50, (1001, 3)).astype(dtype)
    points[17, 1] = -0.0
    low, high = column_bounds(points)
    assert low.dtype == high.dtype == points.dtype
    assert np.array_equal(low, points.min(axis=0)) and np.array_equal(high, points.max(axis=0))


def test_column_bounds_of_no_points_is_an_error_as_numpys():
    with pytest.raises(ValueError):
        column_bounds(np.zeros((0, 3)))


def test_unit_vectors_are_unit_and_a_too_short_one_is_zero():
    unit, length = unit_vectors_and_lengths(np.array([[3.0, 4.0, 0.0], [MIN_LENGTH / 2, 0.0, 0.0]]))
    assert np.allclose(unit[0], [0.6, 0.8, 0.0]) and length[0] == 5.0 and not unit[1].any()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_row_bounds_are_numpys_per_row_min_and_max(dtype):
    values = np.random.default_rng(1).normal(0, 5, (999, 3)).astype(dtype)
    low, high = row_bounds(values)
    assert np.array_equal(low, values.min(axis=1)) and np.array_equal(high, values.max(axis=1))


def test_dot3_is_einsums_dot_product_bit_for_bit_broadcast_or_gathered():
    rng = np.random.default_rng(2)
    corners, vectors = rng.normal(size=(5000, 3, 3)), rng.normal(size=(5000, 3))
    picked = rng.normal(size=(40, 3))[rng.integers(0, 40, 5000)]
    assert np.array_equal(dot3(vectors, picked), np.einsum("fi,fi->f", vectors, picked))
    assert np.array_equal(dot3(corners, vectors[:, None, :]), np.einsum("fci,fi->fc", corners, vectors))
    assert np.array_equal(dot3(vectors[:, None, :], corners), np.einsum("pj,pij->pi", vectors, corners))
    np.testing.assert_allclose(dot3(vectors, picked), (vectors * picked).sum(axis=1), rtol=1e-12, atol=1e-12)
