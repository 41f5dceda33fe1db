"""Specification of grafting (thesis 003 Algorithms 5, 7, 8) and radius smoothing."""
import numpy as np
import pytest

from species.errors import ParameterError
from species.lsystem.graft import extract_subtree, graft, pipe_smooth_radius, side_anchor, smooth_radius, subtree_mask
from species.lsystem.lstring_io import lstring_to_tree
from species.skeleton import Skeleton
from fixtures.skeletons import fork_with_leaves


def trunk(n=4, radius=0.1) -> Skeleton:
    z = np.arange(n, dtype=float)
    return Skeleton(np.stack([0 * z, 0 * z, z], 1), np.arange(-1, n - 1), np.full(n, radius), np.zeros(n))


def fork() -> Skeleton:
    """A subtree: one edge up, then two edges up-left and up-right (root at (5, 5, 5), away from the origin)."""
    positions = np.array([[5, 5, 5], [5, 5, 6], [5, 5.5, 6.5], [5, 4.5, 6.5]], float)
    return Skeleton(positions, [-1, 0, 1, 1], [0.05, 0.04, 0.02, 0.02], [0, 0, 1, 1])


def test_side_anchor_follows_algorithm_5():
    skeleton, anchor = side_anchor(trunk(), 1, camera_position=[10, 0, 1], right=True)
    # toCam = +x, trunkDir = +z: side = x cross z = -y; newDir = normalize(-y + 0.3 z); length 1 * 0.6.
    direction = np.array([0, -1, 0.3]) / np.linalg.norm([0, -1, 0.3])
    assert anchor == 4 and skeleton.parent[anchor] == 1
    assert np.allclose(skeleton.positions[anchor], [0, 0, 1] + 0.6 * direction, atol=1e-6)
    assert np.isclose(skeleton.radius[anchor], 0.08) and skeleton.order[anchor] == 1


def test_left_anchor_mirrors_right():
    right = side_anchor(trunk(), 1, [10, 0, 1], right=True)[0].positions[-1]
    left = side_anchor(trunk(), 1, [10, 0, 1], right=False)[0].positions[-1]
    assert np.allclose(right * [1, -1, 1], left, atol=1e-6)


def test_side_anchor_rejects_a_tip_and_a_camera_on_the_axis():
    with pytest.raises(ParameterError, match="'node'"):
        side_anchor(trunk(), 3, [10, 0, 0])
    with pytest.raises(ParameterError, match="'camera_position'"):
        side_anchor(trunk(), 1, [0, 0, 10])


def test_graft_attaches_the_subtree_root_at_the_anchor():
    base, anchor = side_anchor(trunk(), 1, [10, 0, 1])
    grown = graft(base, anchor, fork())
    assert len(grown) == len(base) + len(fork()) - 1
    assert grown.parent[len(base)] == anchor
    assert np.all(grown.parent[1:] < np.arange(1, len(grown)))


def test_graft_turns_the_first_edge_along_the_anchor_edge_and_keeps_lengths():
    base, anchor = side_anchor(trunk(), 1, [10, 0, 1])
    grown = graft(base, anchor, fork())
    first = grown.positions[len(base)] - grown.positions[anchor]
    anchor_edge = base.positions[anchor] - base.positions[1]
    assert np.allclose(first / np.linalg.norm(first), anchor_edge / np.linalg.norm(anchor_edge), atol=1e-6)
    assert np.allclose(grown.segment_lengths[len(base):], fork().segment_lengths[1:], atol=1e-6)


def test_graft_shifts_orders_by_the_anchor_order():
    base, anchor = side_anchor(trunk(), 1, [10, 0, 1])
    grown = graft(base, anchor, fork())
    assert grown.order[len(base):].tolist() == [1, 2, 2]


def test_graft_of_a_parsed_lstring_with_ratio_smoothing_follows_algorithm_8():
    base, anchor = side_anchor(trunk(), 1, [10, 0, 1])
    subtree = lstring_to_tree("[&(90)F(0.5)[+(0)&(45)F(0.3)][+(180)&(45)F(0.3)]]", np.random.default_rng(0))
    grown = graft(base, anchor, subtree, smoothing="ratio", ratio=0.8)
    relative_depth = grown.depth[len(base):] - grown.depth[anchor]
    assert np.allclose(grown.radius[len(base):], grown.radius[anchor] * 0.8 ** relative_depth)


def test_smooth_radius_sets_base_times_ratio_to_the_depth():
    smoothed = smooth_radius(trunk(radius=0.1), 1, ratio=0.5)
    assert np.allclose(smoothed.radius, [0.1, 0.1, 0.05, 0.025])


def test_smooth_radius_leaves_other_subtrees_alone():
    base = graft(*side_anchor(trunk(), 1, [10, 0, 1]), fork())
    smoothed = smooth_radius(base, 4, ratio=0.5)
    outside = ~subtree_mask(base, 4)
    assert np.array_equal(smoothed.radius[outside], base.radius[outside])


def test_pipe_smoothing_clamps_children_to_the_start_radius_and_never_grows_outward():
    base, anchor = side_anchor(trunk(radius=0.01), 1, [10, 0, 1])
    grown = graft(base, anchor, fork(), smoothing="pipe")
    below = np.flatnonzero(subtree_mask(grown, anchor))[1:]
    assert np.all(grown.radius[below] <= grown.radius[grown.parent[below]] + 1e-7)
    assert np.all(grown.radius[below] <= grown.radius[anchor])


def test_pipe_smoothing_applies_the_pipe_rule_below_the_start():
    tree = Skeleton(np.array([[0, 0, 0], [0, 0, 1], [0, 0, 2], [1, 0, 2], [-1, 0, 2]], float), [-1, 0, 1, 2, 2],
                    [1.0, 1.0, 0.9, 0.02, 0.02], np.zeros(5))
    smoothed = pipe_smooth_radius(tree, 1, exponent=2.5)
    assert np.isclose(smoothed.radius[2], (2 * 0.02 ** 2.5) ** (1 / 2.5), rtol=1e-5)
    assert smoothed.radius[1] == tree.radius[1]


def test_graft_rejects_the_root_as_anchor():
    with pytest.raises(ParameterError, match="'anchor'"):
        graft(trunk(), 0, fork())


def test_extract_subtree_is_the_masked_nodes_renumbered_with_the_root_at_start():
    tree = fork_with_leaves()
    mask = subtree_mask(tree, 5)
    sub = extract_subtree(tree, 5)
    assert len(sub) == mask.sum() == 4
    assert np.all(sub.parent[1:] < np.arange(1, len(sub))) and sub.parent[0] == -1
    np.testing.assert_array_equal(sub.positions, tree.positions[mask])
    np.testing.assert_array_equal(sub.positions[0], tree.positions[5])
    np.testing.assert_array_equal(sub.radius, tree.radius[mask])
    assert sub.order.tolist() == [0, 0, 1, 1]  # orders shifted so the subtree's root is order 0


def test_extract_subtree_keeps_the_leaves_that_hang_on_its_nodes():
    tree = fork_with_leaves()
    sub = extract_subtree(tree, 5)
    kept = np.isin(tree.leaf_node, np.flatnonzero(subtree_mask(tree, 5)))
    assert sub.n_leaves == kept.sum() == 2
    np.testing.assert_array_equal(sub.leaves, tree.leaves[kept])
    np.testing.assert_array_equal(sub.positions[sub.leaf_node], tree.positions[tree.leaf_node[kept]])


def test_extract_subtree_of_the_root_is_the_whole_tree_and_a_bad_start_is_rejected():
    tree = fork()
    whole = extract_subtree(tree, 0)
    for name, array in tree.to_arrays().items():
        np.testing.assert_array_equal(getattr(whole, name), array)
    with pytest.raises(ParameterError, match="'start'"):
        extract_subtree(tree, 99)
