"""Specification of tree <-> L-string (thesis 003 Algorithms 4 and 6) in the Z-up world."""
import re

import numpy as np
import pytest

from species.lsystem.graft import subtree_mask
from species.lsystem.generator import grow
from species.lsystem.lstring_io import (LStringError, branch_orders, edge_angles, lstring_round_trip, lstring_to_tree,
                                       tree_to_lstring)
from species.skeleton import Skeleton

TREE = {"generator": "lsystem", "axiom": "X", "rules": ["X -> F[&X]/(137.5)[&X]", "F -> FF"], "iterations": 4,
        "angle": 35.0, "step": 0.3, "tropism": [0.0, 0.0, -0.1], "angle_jitter": 10.0}


def two_edges(*ends) -> Skeleton:
    positions = np.array([[0, 0, 0], *ends], float)
    return Skeleton(positions, [-1] + [0] * len(ends), np.full(len(positions), 0.01), np.zeros(len(positions)))


@pytest.mark.parametrize("direction, yaw, pitch", [
    ([1, 0, 0], 0.0, 0.0), ([0, -1, 0], 90.0, 0.0), ([0, 1, 0], -90.0, 0.0), ([0, 0, 1], 0.0, 90.0),
    ([1, 0, -1], 0.0, -45.0),
])
def test_yaw_is_thesis_yaw_after_y_up_to_z_up(direction, yaw, pitch):
    got_yaw, got_pitch, _ = edge_angles(np.array([direction], float))
    assert np.allclose([got_yaw[0], got_pitch[0]], [yaw, pitch])


def test_both_angles_are_always_written_with_three_decimals():
    text = tree_to_lstring(two_edges([1.0, 0, 0], [0, 0, 2.5]))
    assert text == "[+(0.000)&(0.000)F(1.000)][+(0.000)&(90.000)F(2.500)]"


def test_negative_angles_use_minus_and_caret():
    text = tree_to_lstring(two_edges([0, 1.0, -1.0]))
    assert text == "[-(90.000)^(45.000)F(1.414)]"


def test_every_edge_is_one_bracketed_forward():
    skeleton = grow(TREE, np.random.default_rng(0))
    text = tree_to_lstring(skeleton)
    assert text.count("F(") == len(skeleton) - 1 == text.count("[") == text.count("]")
    assert all(len(n.split(".")[1]) == 3 for n in re.findall(r"\(([^)]*)\)", text))


def test_round_trip_without_noise_returns_the_same_nodes():
    skeleton = grow(TREE, np.random.default_rng(0))
    rebuilt = lstring_to_tree(tree_to_lstring(skeleton), np.random.default_rng(1), degree_diff=0,
                              dist_diff_percent=0)
    assert np.array_equal(rebuilt.parent, skeleton.parent)
    assert np.allclose(rebuilt.positions, skeleton.positions, atol=5e-3)


def test_round_trip_of_a_subtree_is_relative_to_its_root():
    skeleton = grow(TREE, np.random.default_rng(0))
    node = int(skeleton.children(skeleton.children(1)[0])[0])
    nodes = np.flatnonzero(subtree_mask(skeleton, node))  # turtle output is preorder, as Algorithm 6 builds
    rebuilt = lstring_to_tree(tree_to_lstring(skeleton, node), np.random.default_rng(1), 0, 0)
    assert len(rebuilt) == len(nodes)
    assert np.allclose(rebuilt.positions, skeleton.positions[nodes] - skeleton.positions[node], atol=5e-3)


def breadth_first(skeleton: Skeleton) -> Skeleton:
    """The same tree with its nodes renumbered level by level (as reconstructions number them), so the string's
    depth-first order is not the index order."""
    order = np.argsort(skeleton.depth, kind="stable")
    new_index = np.empty_like(order)
    new_index[order] = np.arange(len(order))
    parent = np.where(skeleton.parent[order] < 0, -1, new_index[np.maximum(skeleton.parent[order], 0)])
    return Skeleton(skeleton.positions[order], parent, skeleton.radius[order], skeleton.order[order])


@pytest.mark.parametrize("node", [0, 3])
def test_round_trip_without_the_text_is_the_same_tree_and_draws(node):
    skeleton = breadth_first(grow(TREE, np.random.default_rng(0)))
    # edges whose angles round to zero from below ('-(0.000)') and lengths on a rounding boundary
    positions = skeleton.positions.copy()
    positions[5] = positions[skeleton.parent[5]] + [1.0, -1e-9, 2.0005]
    skeleton = Skeleton(positions, skeleton.parent, skeleton.radius, skeleton.order)
    rng_text, rng_direct = np.random.default_rng(7), np.random.default_rng(7)
    via_text = lstring_to_tree(tree_to_lstring(skeleton, node), rng_text, 10, 0.15, tip_radius=0.01)
    direct = lstring_round_trip(skeleton, rng_direct, 10, 0.15, tip_radius=0.01, node=node)
    for key in ("positions", "parent", "radius", "order"):
        assert np.array_equal(getattr(direct, key), getattr(via_text, key)), key
    assert rng_text.random() == rng_direct.random()
    with pytest.raises(LStringError, match="no child"):
        lstring_round_trip(skeleton, rng_direct, node=int(skeleton.tips[0]))


def test_noise_changes_lengths_within_the_percent_and_is_seeded():
    skeleton = grow(TREE, np.random.default_rng(0))
    text = tree_to_lstring(skeleton)
    a = lstring_to_tree(text, np.random.default_rng(5), degree_diff=10, dist_diff_percent=0.15)
    b = lstring_to_tree(text, np.random.default_rng(5), degree_diff=10, dist_diff_percent=0.15)
    assert np.array_equal(a.positions, b.positions)
    ratio = a.segment_lengths[1:] / skeleton.segment_lengths[1:]
    assert np.all((ratio > 0.85 - 1e-3) & (ratio < 1.15 + 1e-3)) and ratio.std() > 0.01


def test_setters_are_absolute_not_accumulated():
    tree = lstring_to_tree("+(90.000)&(0.000)F(1.000)F(1.000)", np.random.default_rng(0), 0, 0)
    assert np.allclose(tree.positions, [[0, 0, 0], [0, -1, 0], [0, -2, 0]], atol=1e-9)


def test_bare_forward_reuses_the_last_distance():
    tree = lstring_to_tree("&(90)F(0.5)F", np.random.default_rng(0), 0, 0)
    assert np.allclose(tree.positions[:, 2], [0, 0.5, 1.0])


@pytest.mark.parametrize("text, problem", [
    ("[+(10)F(1)", "unclosed"), ("F(1)]", "closes no"), ("+F(1)", "needs a number"), ("F(abc)", "needs a number"),
    ("F(1)%", "unexpected"), ("[+(10)]", "no F"),
])
def test_unreadable_lstrings_are_rejected(text, problem):
    with pytest.raises(LStringError, match=problem):
        lstring_to_tree(text, np.random.default_rng(0))


def test_branch_orders_continue_the_straightest_child():
    positions = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 1.2], [0, 0.1, 2], [0, 0.1, 3]], float)
    assert branch_orders(positions, np.array([-1, 0, 1, 1, 3])).tolist() == [0, 0, 1, 0, 0]
