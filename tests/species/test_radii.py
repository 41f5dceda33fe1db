"""Specification of species.geometry.radii: pipe-model radii from the tips to the root."""
import numpy as np
import pytest

from species.errors import ParameterError
from species.geometry.radii import pipe_model_radii
from species.geometry.topology import depth_levels, node_depths


def test_fork_combines_children_by_the_pipe_rule():
    # 0 - 1 - {2, 3}: node 1 (and 0 above it) carries both tips.
    radius = pipe_model_radii(np.array([-1, 0, 1, 1]), 0.01, exponent=2.5)
    np.testing.assert_allclose(radius[2:], 0.01, rtol=1e-6)
    np.testing.assert_allclose(radius[1], (2 * 0.01 ** 2.5) ** (1 / 2.5), rtol=1e-6)
    assert radius[0] == radius[1]


def test_exponent_two_preserves_cross_section_area():
    parent = np.array([-1, 0, 0, 0, 1, 1])
    radius = pipe_model_radii(parent, np.array([1, 1, 0.2, 0.3, 0.1, 0.4]), exponent=2.0).astype(float)
    np.testing.assert_allclose(radius[0] ** 2, radius[1] ** 2 + radius[2] ** 2 + radius[3] ** 2, rtol=1e-6)
    np.testing.assert_allclose(radius[1] ** 2, 0.1 ** 2 + 0.4 ** 2, rtol=1e-6)


def test_radius_never_grows_toward_the_tips():
    rng = np.random.default_rng(3)
    parent = np.concatenate([[-1], [rng.integers(0, i) for i in range(1, 500)]])
    radius = pipe_model_radii(parent, 0.005)
    assert np.all(radius[1:] <= radius[parent[1:]] * (1 + 1e-6))


def test_depths_count_edges_from_the_root():
    np.testing.assert_array_equal(node_depths(np.array([-1, 0, 1, 0, 3, 4])), [0, 1, 2, 1, 2, 3])


def test_parent_after_child_is_rejected():
    with pytest.raises(ParameterError, match="parent"):
        pipe_model_radii(np.array([-1, 2, 0]), 0.01)


def test_non_positive_tip_radius_is_rejected():
    with pytest.raises(ParameterError, match="tip_radius"):
        pipe_model_radii(np.array([-1, 0]), 0.0)


def test_depth_levels_sweep_root_to_tips_or_tips_to_root_in_index_order():
    depth = node_depths(np.array([-1, 0, 1, 0, 3, 4, 0]))
    assert [list(level) for level in depth_levels(depth)] == [[1, 3, 6], [2, 4], [5]]
    assert [list(level) for level in depth_levels(depth, first=2, tips_first=True)] == [[5], [2, 4]]
    assert [list(level) for level in depth_levels(node_depths(np.array([-1])))] == []
