"""Skeleton: validation of its arrays and its derived views."""
import numpy as np
import pytest

from species.skeleton import Skeleton, SkeletonError
from fixtures.skeletons import fork_with_leaves


def fork() -> Skeleton:
    # trunk 0-1-2-3, a branch 4-5 from node 1, a thinner same-order split 6 from node 2
    pos = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [0, 0, 3], [1, 0, 1.5], [2, 0, 2], [0.5, 0, 2.8]]
    return Skeleton(pos, [-1, 0, 1, 2, 1, 4, 2], [0.3, 0.25, 0.2, 0.1, 0.1, 0.05, 0.08], [0, 0, 0, 0, 1, 1, 0])


def test_arrays_are_read_only_and_typed():
    s = fork()
    assert s.positions.dtype == np.float32 and s.parent.dtype == np.int32 and s.order.dtype == np.uint8
    with pytest.raises(ValueError):
        s.positions[0, 0] = 1.0


def test_derived_topology_of_a_fork():
    s = fork()
    assert s.depth.tolist() == [0, 1, 2, 3, 2, 3, 3]
    assert s.tips.tolist() == [3, 5, 6]
    assert s.children(1).tolist() == [2, 4]
    assert s.continuation.tolist() == [1, 2, 3, -1, 5, -1, -1]
    assert [p.tolist() for p in s.branch_paths] == [[0, 1, 2, 3], [1, 4, 5], [2, 6]]
    assert s.order_counts().tolist() == [2, 1]


def test_measures_of_a_fork():
    s = fork()
    assert s.height == pytest.approx(3.0)
    assert s.crown_radius == pytest.approx(2.0)
    assert s.total_length == pytest.approx(3 + np.hypot(1, 0.5) + np.hypot(1, 0.5) + np.hypot(0.5, 0.8), rel=1e-6)


def test_npz_round_trip(tmp_path):
    s = fork()
    s.save(tmp_path / "tree.npz")
    back = Skeleton.load(tmp_path / "tree.npz")
    for name, array in s.to_arrays().items():
        assert np.array_equal(array, getattr(back, name))


@pytest.mark.parametrize("parent, message", [([0, 0], "node 0 must be the root"), ([-1, 1], "parent\\[1\\] = 1"),
                                             ([-1, -1], "parent\\[1\\] = -1")])
def test_rejects_bad_topology(parent, message):
    with pytest.raises(SkeletonError, match=message):
        Skeleton([[0, 0, 0], [0, 0, 1]], parent, [0.1, 0.1], [0, 0])


def test_rejects_non_positive_radius_and_nan():
    with pytest.raises(SkeletonError, match="radius"):
        Skeleton([[0, 0, 0], [0, 0, 1]], [-1, 0], [0.1, 0.0], [0, 0])
    with pytest.raises(SkeletonError, match="NaN"):
        Skeleton([[0, 0, 0], [0, np.nan, 1]], [-1, 0], [0.1, 0.1], [0, 0])


def test_subset_keeps_the_chosen_nodes_in_order_with_their_leaves():
    s = fork_with_leaves()
    keep = np.ones(len(s), bool)
    keep[[8, 9]] = False  # the order-2 twig and the leaf on its tip
    sub = s.subset(keep)
    assert len(sub) == 8 and np.array_equal(sub.positions, s.positions[keep])
    assert np.array_equal(sub.parent, s.parent[keep]) and np.array_equal(sub.order, s.order[keep])
    assert np.array_equal(sub.leaf_node, [7]) and np.array_equal(sub.leaves[0], s.leaves[2])


def test_subset_rejects_a_mask_that_orphans_a_node_or_has_the_wrong_shape():
    s = fork()
    with pytest.raises(SkeletonError, match="drops node 1 but keeps its child"):
        s.subset(np.array([True, False, True, True, True, True, True]))
    with pytest.raises(SkeletonError, match="bool mask"):
        s.subset(np.ones(3, bool))
