"""reconstruct.metrics: known answers of every metric, the trees-row decoder on a real tiny dataset, rejections.

Skeletons here are a few hand-placed nodes; the dataset rows are a 2-tree shard without views, written by the
pipeline's shard writer.
"""
from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from scipy.spatial import cKDTree

import farm.dataset as dataset
import species
from farm.jobs import parse_spec
from farm.pipeline import plan_shards, run_shard
from farm.dataset.storage import Location
from farm.tree_chain import SpeciesChain
from reconstruct.metrics import (RADIUS_MULTIPLES, MetricError, foreground_depth_error, height_crown_errors,
                                 image_plane_hausdorff, node_distances, parameter_scores, silhouette_iou,
                                 skeleton_precision_recall, surface_distances, unit_cube_hausdorff)
from reconstruct.scoring import main_branch_nodes, main_branch_points
from renderers.camera import orthographic_camera
from species import MeshPart, Skeleton, TreeMesh
from trainers.sketchnet_codec import REGRESSION_HEADS, ParameterCodec


def _tree(shift=(0.0, 0.0, 0.0), with_branch: bool = True) -> Skeleton:
    """A 4 m trunk (nodes 1 m apart) with a 1 m side branch from its middle; radii 0.1 m down to 0.05 m."""
    trunk = [[0, 0, z] for z in range(5)]
    branch = [[0.5, 0, 2.5], [1.0, 0, 3.0]] if with_branch else []
    positions = np.array(trunk + branch, float) + np.asarray(shift)
    parent = [-1, 0, 1, 2, 3] + ([2, 5] if with_branch else [])
    radius = [0.1, 0.09, 0.08, 0.07, 0.06] + ([0.05, 0.05] if with_branch else [])
    return Skeleton(positions, parent, radius, np.zeros(len(positions)) if not with_branch else [0] * 5 + [1, 1])


# ------------------------------------------------------------------------------------------------ depth
def test_depth_error_averages_only_the_foreground():
    predicted = np.array([[0.5, 0.5], [0.0, 0.0]])
    target = np.array([[0.4, 0.8], [1.0, 1.0]])
    mask = np.array([[1, 1], [0, 0]])
    assert foreground_depth_error(predicted, target, mask) == pytest.approx(0.2)


def test_depth_error_up_to_mirror_forgives_a_tree_seen_from_behind_and_nothing_else():
    rng = np.random.default_rng(0)
    target = rng.uniform(0.0, 1.0, (16, 16))
    mask = np.ones((16, 16))
    mirrored = 1.0 - target  # the mirror tree's depth: the same strokes from the same side
    assert foreground_depth_error(mirrored, target, mask) > 0.2
    assert foreground_depth_error(mirrored, target, mask, up_to_mirror=True) == pytest.approx(0.0)
    off = np.clip(target + 0.1, 0, 1)
    assert foreground_depth_error(off, target, mask, up_to_mirror=True) == pytest.approx(
        foreground_depth_error(off, target, mask))


def test_depth_error_scores_only_the_named_channels_pooled_over_the_batch():
    predicted = np.zeros((2, 3, 1, 2))
    target = np.zeros((2, 3, 1, 2))
    target[:, 0] = 0.1
    target[:, 1] = 0.3
    target[:, 2] = 1.0
    mask = np.ones((2, 1, 1, 2))
    mask[1, 0, 0, 1] = 0
    assert foreground_depth_error(predicted, target, mask, channels=(0, 1)) == pytest.approx(0.2)


def test_depth_error_rejects_an_empty_mask_mismatched_shapes_and_nan():
    depth = np.zeros((4, 4))
    with pytest.raises(MetricError, match="no foreground"):
        foreground_depth_error(depth, depth, np.zeros((4, 4)))
    with pytest.raises(MetricError, match="one shape"):
        foreground_depth_error(depth, np.zeros((4, 5)), np.ones((4, 4)))
    with pytest.raises(MetricError, match="does not fit"):
        foreground_depth_error(np.zeros((2, 4, 4)), np.zeros((2, 4, 4)), np.ones((2, 4, 4)))
    with pytest.raises(MetricError, match="NaN"):
        foreground_depth_error(np.full((4, 4), np.nan), depth, np.ones((4, 4)))
    with pytest.raises(MetricError, match="channels"):
        foreground_depth_error(np.zeros((2, 4, 4)), np.zeros((2, 4, 4)), np.ones((4, 4)), channels=(2,))


# ------------------------------------------------------------------------------------------------ distances
def test_identical_node_sets_are_at_distance_zero():
    distances = node_distances(_tree(), _tree(), height=4.0)
    assert distances.hausdorff == distances.chamfer == distances.hausdorff_95 == 0.0


def test_a_shifted_copy_is_at_the_shift_over_the_height():
    shift = np.array([0.03, -0.04, 0.0])  # 0.05 m, far below the 0.5 m node spacing
    distances = node_distances(_tree(shift), _tree(), height=4.0)
    assert distances.hausdorff == pytest.approx(0.05 / 4.0)
    assert distances.chamfer == pytest.approx(0.05 / 4.0)


def test_chamfer_is_the_mean_of_the_two_directed_means():
    a = np.array([[0.0, 0, 0]])
    b = np.array([[0.0, 0, 0], [2.0, 0, 0]])
    distances = node_distances(a, b, height=1.0)
    assert distances.hausdorff == pytest.approx(2.0)
    assert distances.chamfer == pytest.approx(0.5 * (0.0 + 1.0))


def test_unit_cube_hausdorff_divides_by_the_true_orthographic_volume():
    true = np.array([[0.0, 0, 0], [0, 0, 4.0], [1.0, 0, 2.0]])  # largest extent 4 m
    predicted = true + [0.0, 0.0, 0.2]
    assert unit_cube_hausdorff(predicted, true) == pytest.approx(0.2 / (1.05 * 4.0))
    # A box given explicitly is used for both sets.
    box = np.array([[0, 0, 0], [10.0, 1, 1]])
    assert unit_cube_hausdorff(predicted, true, box=box) == pytest.approx(0.2 / (1.05 * 10.0))


def test_unit_cube_hausdorff_of_a_skeleton_uses_its_bounds():
    tree = _tree()
    extent = float((tree.bounds[1] - tree.bounds[0]).max())
    assert unit_cube_hausdorff(_tree((0, 0, 0.1)), tree) == pytest.approx(0.1 / (1.05 * extent), rel=1e-6)


def test_image_plane_hausdorff_ignores_depth_and_divides_by_the_image():
    true = np.array([[0.0, 0, 0], [0, 0, 4.0], [1.0, 0, 2.0]])
    camera = orthographic_camera(true, 0.0, 0.0, 200)  # looks along +y: depth is y
    pixels_per_metre = camera.K[0, 0]
    assert image_plane_hausdorff(true + [0.0, 3.0, 0.0], true, camera) == pytest.approx(0.0, abs=1e-9)
    shifted = true + [0.0, 0.0, 0.2]
    assert image_plane_hausdorff(shifted, true, camera) == pytest.approx(0.2 * pixels_per_metre / 200, rel=1e-6)


def test_main_branch_points_lie_on_the_main_branches_no_farther_apart_than_asked():
    tree = _tree()
    points = main_branch_points(tree, divisions=64)
    nodes = main_branch_nodes(tree)
    assert cKDTree(points).query(nodes)[0].max() < 1e-6  # every main node is among the points
    gaps = cKDTree(points).query(points, k=2)[0][:, 1]
    assert gaps.max() <= tree.height / 64 + 1e-6


def _square(z: float) -> TreeMesh:
    """A 1 m x 1 m horizontal square of bark at height z (two triangles), no leaves."""
    vertices = np.array([[0, 0, z], [1, 0, z], [1, 1, z], [0, 1, z]], float)
    bark = MeshPart(vertices, [[0, 1, 2], [0, 2, 3]], np.tile([0.0, 0, 1], (4, 1)), vertices[:, :2])
    return TreeMesh(bark, MeshPart.empty())


def test_surface_distances_of_parallel_squares_are_their_gap_over_the_height():
    # Samples 1/sqrt(4000) m apart: each nearest sample is 0.5 m away plus a sideways offset of about 0.01 m.
    distances = surface_distances(_square(0.0), _square(0.5), 2.0, 4000, np.random.default_rng(5))
    assert distances.chamfer == pytest.approx(0.25, rel=0.005)
    assert distances.hausdorff == pytest.approx(0.25, rel=0.01)
    assert distances.hausdorff_95 <= distances.hausdorff


def test_surface_distances_are_reproducible_from_the_generator():
    params = species.sample("sc_dome_shrub", np.random.default_rng(1))
    _, mesh = species.rebuild(params)
    first = surface_distances(mesh, mesh, 2.0, 500, np.random.default_rng(5))
    assert first == surface_distances(mesh, mesh, 2.0, 500, np.random.default_rng(5))
    assert first != surface_distances(mesh, mesh, 2.0, 500, np.random.default_rng(6))


def test_surface_distances_reject_an_empty_mesh_and_a_missing_generator():
    mesh = _square(0.0)
    with pytest.raises(MetricError, match="no surface"):
        surface_distances(mesh, TreeMesh(MeshPart.empty(), MeshPart.empty()), 2.0, 10, np.random.default_rng(0))
    with pytest.raises(MetricError, match="TreeMesh"):
        surface_distances(mesh, np.zeros((3, 3)), 2.0, 10, np.random.default_rng(0))
    with pytest.raises(MetricError, match="Generator"):
        surface_distances(mesh, mesh, 2.0, 10, 0)
    with pytest.raises(MetricError, match="surface samples"):
        surface_distances(mesh, mesh, 2.0, 0, np.random.default_rng(0))


def test_point_sets_reject_empty_sets_bad_shapes_nan_and_bad_heights():
    points = np.zeros((3, 3))
    with pytest.raises(MetricError, match="empty"):
        node_distances(np.zeros((0, 3)), points, 1.0)
    with pytest.raises(MetricError, match="shape"):
        node_distances(np.zeros((3, 2)), points, 1.0)
    with pytest.raises(MetricError, match="NaN"):
        node_distances(np.full((3, 3), np.nan), points, 1.0)
    with pytest.raises(MetricError, match="not numeric"):
        node_distances("nodes", points, 1.0)
    for height in (0.0, -1.0, np.nan, "tall"):
        with pytest.raises(MetricError, match="height"):
            node_distances(points, points, height)
    with pytest.raises(MetricError, match="spans no volume"):
        unit_cube_hausdorff(points, np.zeros((1, 3)))


# ------------------------------------------------------------------------------------------------ precision / recall
def test_an_identical_skeleton_scores_one_at_every_radius_multiple():
    match = skeleton_precision_recall(_tree(), _tree())
    assert match.thresholds.shape == match.f1.shape == (101,)
    np.testing.assert_array_equal(match.thresholds, RADIUS_MULTIPLES)
    assert np.all(match.precision == 1.0) and np.all(match.recall == 1.0)
    assert match.auc == 1.0


def test_a_missing_branch_lowers_recall_but_not_precision():
    match = skeleton_precision_recall(_tree(with_branch=False), _tree())
    assert np.all(match.precision == 1.0)
    # The branch is sqrt(0.5) + sqrt(0.5) m of the 5.41 m tree; its first points lie within t x 0.05 m of the trunk.
    branch_share = np.sqrt(2) / (4 + np.sqrt(2))
    assert match.recall[-1] < 1.0
    assert match.recall[0] == pytest.approx(1 - branch_share)
    assert match.auc < 1.0


def test_a_shift_of_half_a_radius_matches_from_t_one_half():
    # Every radius is 0.1 m; shifted sideways by 0.05 m, every point is 0.05 m = 0.5 x r from the other skeleton.
    def pole(dx):
        return Skeleton([[dx, 0, 0], [dx, 0, 1], [dx, 0, 2]], [-1, 0, 1], [0.1, 0.1, 0.1], [0, 0, 0])

    match = skeleton_precision_recall(pole(0.05), pole(0.0))
    t = match.thresholds
    np.testing.assert_array_equal(match.precision, np.where(t >= 0.5 - 1e-12, 1.0, 0.0))
    np.testing.assert_array_equal(match.recall, match.precision)
    assert match.auc == pytest.approx(0.5 + 0.5 * 0.01)  # F1 jumps to 1 at t = 0.5: trapezoid over 0.49..0.5


def test_precision_recall_rejects_skeletons_without_length():
    with pytest.raises(MetricError, match="no branch length"):
        skeleton_precision_recall(Skeleton(np.zeros((1, 3)), [-1], [0.1], [0]), _tree())
    with pytest.raises(MetricError, match="Skeleton"):
        skeleton_precision_recall(np.zeros((3, 3)), _tree())
    with pytest.raises(MetricError, match="spacing"):
        skeleton_precision_recall(_tree(), _tree(), spacing=0.0)


# ------------------------------------------------------------------------------------------------ silhouettes
def test_silhouette_iou_of_known_masks():
    a = np.zeros((4, 4), bool)
    b = np.zeros((4, 4), np.uint8)
    a[:, :2] = True          # 8 pixels
    b[:, 1:3] = 255          # 8 pixels, 4 shared
    assert silhouette_iou(a, b) == pytest.approx(4 / 12)
    assert silhouette_iou(a, a) == 1.0
    assert silhouette_iou(a, ~a) == 0.0


def test_silhouette_iou_rejects_two_empty_masks_and_mismatched_shapes():
    with pytest.raises(MetricError, match="both masks are empty"):
        silhouette_iou(np.zeros((3, 3)), np.zeros((3, 3)))
    with pytest.raises(MetricError, match="one shape"):
        silhouette_iou(np.zeros((3, 3)), np.zeros((3, 4)))


# ------------------------------------------------------------------------------------------------ parameters, measures
@pytest.fixture(scope="module")
def dictionaries() -> list[dict]:
    return [species.sample(name, np.random.default_rng(i)) for i, name in enumerate(["black_oak", "palm", "cherry"])]


def test_parameter_scores_are_100_for_the_true_dictionaries_and_lower_for_others(dictionaries):
    codec = ParameterCodec.fit(dictionaries)
    perfect = parameter_scores(codec, dictionaries, dictionaries)
    assert set(perfect) == {f"score_{h}" for h in REGRESSION_HEADS} | {"score_overall"}
    assert all(score == pytest.approx(100.0) for score in perfect.values())
    swapped = parameter_scores(codec, dictionaries[::-1], dictionaries)
    assert swapped["score_overall"] < 100.0
    assert parameter_scores(codec, dictionaries[0], dictionaries[0])["score_overall"] == pytest.approx(100.0)
    with pytest.raises(MetricError, match="as many"):
        parameter_scores(codec, dictionaries[:2], dictionaries)


def test_height_and_crown_errors_are_relative_to_the_truth():
    true = _tree()
    taller = Skeleton(true.positions * [1.0, 1.0, 1.5], true.parent, true.radius, true.order)
    errors = height_crown_errors(taller, true)
    assert errors["height"] == pytest.approx(6.0) and errors["true_height"] == pytest.approx(4.0)
    assert errors["height_rel_error"] == pytest.approx(0.5)
    assert errors["crown_radius_rel_error"] == pytest.approx(0.0)
    pole = Skeleton([[0, 0, 0], [0, 0, 1]], [-1, 0], [0.1, 0.1], [0, 0])
    with pytest.raises(MetricError, match="crown_radius"):
        height_crown_errors(true, pole)


# ------------------------------------------------------------------------------------------------ dataset rows
@pytest.fixture(scope="module")
def tree_part(tmp_path_factory) -> pa.Table:
    """The trees part file of a 2-tree shard without views, written by the pipeline's own shard writer (in this
    process: the rows and bytes are those `farm generate` writes, without starting Ray)."""
    spec = parse_spec({"name": "metrics", "seed": 7, "species": {"sc_dome_shrub": 1, "lsystem_bush": 1},
                       "shard_size": 2, "render": {"outputs": []}})
    out = tmp_path_factory.mktemp("metrics") / "dataset"
    [plan] = plan_shards(spec)
    run_shard(spec, plan, Location.resolve(str(out)), SpeciesChain(spec))
    return pq.read_table(out / dataset.part_name("trees", 0), schema=dataset.trees_schema())


def test_skeleton_from_row_rebuilds_the_grown_skeleton(tree_part):
    rows = tree_part.to_pylist()
    assert len(rows) == 2 and not any(row["error"] for row in rows)
    for row in rows:
        skeleton = dataset.skeleton_from_row(row)
        grown, _ = species.rebuild(json.loads(row["params_json"]))
        for name, array in grown.to_arrays().items():
            np.testing.assert_array_equal(getattr(skeleton, name), array, err_msg=name)
        assert skeleton.height == pytest.approx(row["height"])
        assert node_distances(skeleton, grown, skeleton.height).hausdorff == 0.0


def test_skeleton_from_row_reads_pandas_rows_too(tree_part):
    row = tree_part.to_pandas().iloc[1].to_dict()
    from_pandas = dataset.skeleton_from_row(row)
    assert len(from_pandas) == row["n_nodes"]
    from_arrow = dataset.skeleton_from_row(tree_part.to_pylist()[1])
    for name, array in from_arrow.to_arrays().items():
        np.testing.assert_array_equal(getattr(from_pandas, name), array, err_msg=name)


def test_skeleton_from_row_rejects_failed_and_damaged_rows():
    row = {**{name: [] for name in dataset.SKELETON_COLUMNS}, "tree_id": "t-1", "positions": None,
           "error": "TreeTooLargeError: too many nodes"}
    with pytest.raises(dataset.DatasetError, match="t-1 has no skeleton.*too many nodes"):
        dataset.skeleton_from_row(row)
    with pytest.raises(dataset.DatasetError, match="lacks the skeleton columns radius"):
        dataset.skeleton_from_row({"tree_id": "t-2", "positions": [0.0, 0.0, 0.0], "parent": [-1]})
    damaged = {"tree_id": "t-3", "positions": [0.0, 0.0, 0.0, 1.0], "parent": [-1], "radius": [0.1], "order": [0],
               "leaves": [], "leaf_node": []}
    with pytest.raises(dataset.DatasetError, match="3 per node"):
        dataset.skeleton_from_row(damaged)
    bad_parent = {**damaged, "positions": [0.0] * 6, "parent": [-1, 5], "radius": [0.1, 0.1], "order": [0, 0]}
    with pytest.raises(dataset.DatasetError, match="t-3 holds an invalid skeleton: parent"):
        dataset.skeleton_from_row(bad_parent)
