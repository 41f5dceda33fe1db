"""Specification of reconstruct.completion: trunk identification (Algorithm 2), twig pruning (Algorithm 3), grafts
into the crown's gaps (Algorithms 4-8) and the whole editing chain ending in leafy twigs and a mesh."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from reconstruct.completion import (ScanReach, complete, crown_sector_lengths, fill_gaps, GAP_RATIO, identify_trunk,
                                    prune_long_twigs)
from species.errors import ParameterError
from species.geometry.radii import pipe_model_radii
from species.meshing.tubes_and_cards import build_mesh
from species.skeleton import LEAF_CARD_CORNERS, Skeleton


def chain(start, direction, count, step) -> np.ndarray:
    """(count, 3) points stepping from `start` along `direction`."""
    return np.asarray(start, float) + step * np.arange(1, count + 1)[:, None] * np.asarray(direction, float)


def stem_with_branches(azimuths_deg, trunk_nodes=21, height=10.0, branch_nodes=6, step=0.4) -> Skeleton:
    """A vertical stem with one straight, slightly rising branch per azimuth (degrees), spread up the stem."""
    z = np.linspace(0.0, height, trunk_nodes)
    positions = [np.column_stack([0 * z, 0 * z, z])]
    parent = [np.arange(-1, trunk_nodes - 1)]
    count = trunk_nodes
    for k, azimuth in enumerate(np.radians(azimuths_deg)):
        junction = 5 + k % (trunk_nodes - 7)
        positions.append(chain(positions[0][junction], [np.cos(azimuth), np.sin(azimuth), 0.3], branch_nodes, step))
        parent.append(np.concatenate([[junction], count + np.arange(branch_nodes - 1)]))
        count += branch_nodes
    parent = np.concatenate(parent)
    order = (np.arange(count) >= trunk_nodes).astype(int)
    return Skeleton(np.concatenate(positions), parent, pipe_model_radii(parent, 0.01), order)


FULL = np.arange(0.0, 360.0, 22.5)
GAPPY = FULL[FULL >= 90.0]  # the sector from 0 to 90 degrees is emptied


def y_fork(half_angle_deg, radii=(0.1, 0.1)) -> Skeleton:
    """A stem 0-1-2 that splits at node 2 into two leaders, `half_angle_deg` either side of vertical."""
    a = np.radians(half_angle_deg)
    positions = [[0, 0, 0], [0, 0, 1], [0, 0, 2], [np.sin(a), 0, 2 + np.cos(a)], [-np.sin(a), 0, 2 + np.cos(a)]]
    return Skeleton(positions, [-1, 0, 1, 2, 2], [0.2, 0.18, 0.15, *radii], [0, 0, 0, 0, 1])


def test_a_narrow_y_fork_of_equal_leaders_is_all_trunk():
    assert identify_trunk(y_fork(10.0)).tolist() == [True] * 5


def test_a_wide_fork_keeps_only_the_thickest_leader_on_the_trunk():
    assert identify_trunk(y_fork(25.0, radii=(0.1, 0.1))).tolist() == [True, True, True, True, False]
    assert identify_trunk(y_fork(25.0, radii=(0.06, 0.1))).tolist() == [True, True, True, False, True]


def test_a_thin_leader_close_in_angle_is_not_trunk():
    assert identify_trunk(y_fork(5.0, radii=(0.1, 0.06))).tolist() == [True, True, True, True, False]
    assert identify_trunk(y_fork(5.0, radii=(0.1, 0.06)), radius_threshold=0.5).all()


def test_a_main_stem_with_side_branches_is_its_stem():
    tree = stem_with_branches(FULL)
    np.testing.assert_array_equal(identify_trunk(tree), tree.order == 0)


def test_trunk_thresholds_out_of_range_are_rejected():
    with pytest.raises(ParameterError, match="radius_threshold"):
        identify_trunk(y_fork(10.0), radius_threshold=0.0)
    with pytest.raises(ParameterError, match="degree_threshold"):
        identify_trunk(y_fork(10.0), degree_threshold=200.0)


def twiggy() -> tuple[Skeleton, np.ndarray]:
    """A 10-node stem with four side twigs from nodes 1-4, 1, 1, 1 and 5 edges long; the stem's top runs 5 edges
    above its last fork. Twig depths 1, 1, 1, 5, 5: mean 2.6, so twigs are cut back to 2 edges."""
    positions = [chain([0, 0, 0], [0, 0, 1], 9, 1.0)]
    positions.insert(0, np.zeros((1, 3)))
    parent = [np.arange(-1, 9)]
    count = 10
    for junction, length in zip((1, 2, 3, 4), (1, 1, 1, 5)):
        positions.append(chain([0, 0, junction], [1, 0, 0.2], length, 0.3))
        parent.append(np.concatenate([[junction], count + np.arange(length - 1)]))
        count += length
    parent = np.concatenate(parent)
    order = (np.arange(count) >= 10).astype(int)
    leaves = np.tile(np.eye(4, dtype=np.float32) * 0.05, (2, 1, 1))
    tree = Skeleton(np.concatenate(positions), parent, pipe_model_radii(parent, 0.01), order, leaves,
                    [count - 1, 10])  # one leaf at the long twig's tip, one at a short twig's
    return tree, order == 0


def test_pruning_cuts_long_twigs_back_to_the_average_depth():
    tree, trunk = twiggy()
    pruned = prune_long_twigs(tree, trunk)
    assert len(pruned) == len(tree) - 3
    long_twig = pruned.positions[13:]
    np.testing.assert_array_equal(long_twig, tree.positions[13:15])  # 2 of its 5 edges are left
    np.testing.assert_array_equal(pruned.positions, tree.positions[:15])


def test_pruning_never_removes_trunk_nodes_and_drops_leaves_on_removed_nodes():
    tree, trunk = twiggy()
    pruned = prune_long_twigs(tree, trunk)
    np.testing.assert_array_equal(pruned.positions[:10], tree.positions[trunk])
    assert pruned.n_leaves == 1 and pruned.leaf_node.tolist() == [10]


def test_pruning_a_tree_whose_twigs_are_all_as_deep_changes_nothing():
    tree = stem_with_branches(FULL, branch_nodes=2)  # the stem's top is 2 edges above its last fork too
    assert prune_long_twigs(tree, identify_trunk(tree)) is tree


def test_pruning_cuts_by_the_floor_of_the_mean_twig_depth():
    tree = stem_with_branches(FULL)  # 16 twigs 6 edges deep, the stem's top 2: floor(98 / 17) = 5
    pruned = prune_long_twigs(tree, identify_trunk(tree))
    assert len(pruned) == len(tree) - 16


def test_fill_gaps_grafts_branches_into_an_emptied_sector():
    tree = stem_with_branches(GAPPY)
    trunk = identify_trunk(tree)
    before = crown_sector_lengths(tree, trunk)
    assert before[:3].sum() == 0 and np.all(before[3:] > 0)
    filled = fill_gaps(tree, np.random.default_rng(0), trunk_mask=trunk)
    assert len(filled) > len(tree)
    np.testing.assert_array_equal(filled.positions[:len(tree)], tree.positions)  # the measured tree is kept
    grown_trunk = np.concatenate([trunk, np.zeros(len(filled) - len(tree), bool)])
    after = crown_sector_lengths(filled, grown_trunk)
    assert np.all(after[:3] >= GAP_RATIO * np.median(before))
    np.testing.assert_allclose(after[3:], before[3:], atol=0.2 * np.median(before))  # the rest barely changes


def test_grafted_radii_never_grow_from_a_node_to_its_child():
    tree = stem_with_branches(GAPPY)
    filled = fill_gaps(tree, np.random.default_rng(1))
    new = np.arange(len(tree), len(filled))
    assert np.all(filled.radius[new] <= filled.radius[filled.parent[new]] * (1 + 1e-6))


def test_fill_gaps_leaves_a_full_crown_alone():
    tree = stem_with_branches(FULL)
    assert fill_gaps(tree, np.random.default_rng(0)) is tree


def test_fill_gaps_is_deterministic_for_a_seed():
    tree = stem_with_branches(GAPPY)
    first, second = (fill_gaps(tree, np.random.default_rng(7)) for _ in range(2))
    for name, array in first.to_arrays().items():
        np.testing.assert_array_equal(array, getattr(second, name))
    other = fill_gaps(tree, np.random.default_rng(8))
    assert len(other) != len(first) or not np.array_equal(other.positions, first.positions)


def test_complete_gives_a_leafy_tree_that_meshes_with_the_same_bytes_for_a_seed():
    tree = stem_with_branches(GAPPY)
    done = complete(tree, np.random.default_rng(3))
    assert done.n_leaves > 0 and len(done) > len(tree)
    assert np.all(done.order[identify_trunk(tree).nonzero()[0]] == 0)
    glb = build_mesh(done).to_glb()
    assert build_mesh(complete(tree, np.random.default_rng(3))).to_glb() == glb


def test_complete_without_twigs_or_filling_only_prunes():
    tree, _ = twiggy()
    done = complete(tree, np.random.default_rng(0), twigs=None, fill=False)
    assert len(done) == len(tree) - 3 and done.n_leaves == 1


def test_an_unknown_twig_pattern_is_rejected():
    with pytest.raises(ParameterError, match="'twigs'"):
        complete(stem_with_branches(FULL), np.random.default_rng(0), twigs="spiral")


def scan_of(tree: Skeleton, per_segment: int = 5) -> np.ndarray:
    """(P, 3) points along every segment of a skeleton: a scan that sees exactly that tree."""
    child = np.arange(1, len(tree))
    u = np.linspace(0.0, 1.0, per_segment)[:, None, None]
    start, end = tree.positions[tree.parent[child]], tree.positions[child]
    return (start + u * (end - start)).reshape(-1, 3).astype(np.float64)


def assert_inside(tree: Skeleton, measured: Skeleton, reach: ScanReach) -> None:
    """The measured nodes are all there, unchanged; nothing added and no leaf card lies outside the reach."""
    np.testing.assert_array_equal(tree.positions[:len(measured)], measured.positions)
    np.testing.assert_array_equal(tree.parent[:len(measured)], measured.parent)
    added = np.arange(len(tree)) >= len(measured)
    assert not reach.outside(tree.positions[added], tree.radius[added].astype(float)).any()
    corners = np.einsum("mij,cj->mci", tree.leaves[:, :3, :3], LEAF_CARD_CORNERS) + tree.leaves[:, None, :3, 3]
    assert (corners[..., 2] >= reach.ground).all()


def drooping(azimuths_deg) -> Skeleton:
    """Branches from low on the stem that droop to just above the ground: grafts and twigs would reach below it."""
    tree = stem_with_branches(azimuths_deg)
    positions = tree.positions.copy()
    side = tree.order > 0
    positions[side, 2] = np.maximum(positions[side, 2] - 3.0 * np.linalg.norm(positions[side, :2], axis=1), 0.05)
    return Skeleton(positions, tree.parent, tree.radius, tree.order)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("make", [stem_with_branches, drooping])
def test_completion_in_the_scans_reach_never_removes_a_measured_node_nor_goes_below_the_ground(make, seed):
    measured = make(GAPPY)
    reach = ScanReach(scan_of(measured), ground=0.0)
    tree = complete(measured, np.random.default_rng(seed), prune=False, reach=reach)
    assert len(tree) > len(measured) and len(tree.leaves)
    assert_inside(tree, measured, reach)


def test_a_gap_in_the_skeleton_but_not_in_the_scan_is_not_grafted():
    measured = stem_with_branches(GAPPY)
    # The scan is as empty there (an occlusion gap): grafted, as far as a hull margin wide enough for a branch.
    filled = fill_gaps(measured, np.random.default_rng(0), reach=ScanReach(scan_of(measured), 0.0, margin=3.0))
    assert len(filled) > len(measured)
    seen = ScanReach(scan_of(stem_with_branches(FULL)), 0.0)  # the scan has points where the skeleton has none
    assert len(fill_gaps(measured, np.random.default_rng(0), reach=seen)) == len(measured)


def test_the_reach_bounds_by_ground_top_and_hull_margin():
    reach = ScanReach(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2], [1, 1, 2]], float), ground=0.0)
    inside = reach.outside(np.array([[0.5, 0.5, 1.0], [1.5, 0.5, 1.0], [0.5, 0.5, -0.1], [0.5, 0.5, 2.1],
                                     [3.5, 0.5, 1.0], [0.5, 0.5, 0.05]]), np.array([0, 0, 0, 0, 0, 0.1]))
    assert inside.tolist() == [False, False, True, True, True, True]


def test_the_reach_measures_many_positions_block_by_block_as_one_product():
    # ScanReach.outside takes the hull's planes a block of rows at a time: the same answer as the whole product
    rng = np.random.default_rng(4)
    reach = ScanReach(rng.normal(size=(400, 3)) * [2.0, 2.0, 3.0] + [0, 0, 4.0], ground=0.0)
    planes = ConvexHull(reach.points).equations
    for n in (1, 1023, 1024, 1025, 3000):
        xyz = rng.normal(size=(n, 3)) * 4.0 + [0, 0, 4.0]
        radius = rng.random(n) * 0.5
        whole = (xyz @ planes[:, :3].T + planes[:, 3]).max(axis=1) + radius > reach.margin
        low = (xyz[:, 2] - radius < reach.ground) | (xyz[:, 2] > reach.points[:, 2].max())
        expected = low | whole
        assert 0 < expected.sum() < n or n == 1
        assert np.array_equal(reach.outside(xyz, radius), expected)
