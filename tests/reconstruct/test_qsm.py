"""Specification of reconstruct.qsm: the skeleton PLY (vertices with radii, explicit edges) and its round trip, the
QSM measures (DBH by the skeleton and by a circle fit to the scan, crown projection, frustum volumes by order,
lengths) on trees and scans with known answers, their one-row CSV, and the branch table."""
from __future__ import annotations

import csv
import math

import numpy as np
import pandas as pd
import pytest
import trimesh

from reconstruct.qsm import (BRANCH_COLUMNS, ORDER_VOLUME_COLUMNS, QSM_COLUMNS, QsmError, branch_table, qsm_measures,
                             read_skeleton_ply, segment_volumes, write_branch_csv, write_qsm_csv, write_skeleton_ply)
from species.skeleton import Skeleton
from fixtures.skeletons import random_tree


def vertical(z, radius) -> Skeleton:
    """One straight vertical stem through heights `z` (metres) with `radius` at each node."""
    z = np.asarray(z, float)
    return Skeleton(np.column_stack([0 * z, 0 * z, z]), np.arange(-1, len(z) - 1), radius, np.zeros(len(z)))


@pytest.fixture(scope="module")
def tree():
    return random_tree(np.random.default_rng(4), n_nodes=400, n_leaves=10)


@pytest.mark.parametrize("file_format", ["ascii", "binary"])
def test_ply_round_trip_keeps_positions_radii_and_edges(tree, tmp_path, file_format):
    path = tmp_path / f"tree_{file_format}.ply"
    write_skeleton_ply(tree, path, file_format=file_format)
    back = read_skeleton_ply(path)
    tolerance = 1e-6 if file_format == "ascii" else 0.0  # ascii keeps 6 decimals
    np.testing.assert_allclose(back.positions, tree.positions, rtol=0, atol=tolerance)
    np.testing.assert_allclose(back.radius, tree.radius, rtol=0, atol=tolerance)
    np.testing.assert_array_equal(back.parent, tree.parent)


@pytest.mark.parametrize("file_format", ["ascii", "binary"])
def test_trimesh_parses_the_ply_vertices_and_edges(tree, tmp_path, file_format):
    path = tmp_path / "tree.ply"
    write_skeleton_ply(tree, path, file_format=file_format)
    loaded = trimesh.load(path, process=False)
    np.testing.assert_allclose(loaded.vertices, tree.positions, atol=1e-6)
    raw = loaded.metadata["_ply_raw"]
    assert raw["edge"]["length"] == len(tree) - 1
    np.testing.assert_array_equal(raw["edge"]["data"]["vertex1"].ravel(), tree.parent[1:])
    np.testing.assert_allclose(raw["vertex"]["data"]["radius"].ravel(), tree.radius, atol=1e-6)


def test_a_georeferenced_offset_is_written_in_double_and_subtracted_on_reading(tree, tmp_path):
    offset = np.array([4.5e6, 5.7e6, 312.0])
    path = tmp_path / "scan.ply"
    write_skeleton_ply(tree, path, offset=offset)
    assert b"property double x" in path.read_bytes()[:400]
    loaded = trimesh.load(path, process=False)
    np.testing.assert_allclose(loaded.vertices, tree.positions.astype(np.float64) + offset, rtol=0, atol=1e-8)
    np.testing.assert_allclose(read_skeleton_ply(path, offset=offset).positions, tree.positions, atol=1e-6)


def test_an_undirected_shuffled_edge_list_is_rebuilt_from_its_lowest_vertex(tmp_path):
    stem = vertical([0.0, 1.0, 2.0, 3.0], [0.2, 0.15, 0.1, 0.05])
    shuffle = np.array([2, 0, 3, 1])  # file vertex k is stem node shuffle[k]
    where = np.argsort(shuffle)
    edges = np.array([[where[2], where[1]], [where[0], where[1]], [where[3], where[2]]])  # some edges reversed
    rows = [" ".join(f"{v:g}" for v in (*stem.positions[i], stem.radius[i])) for i in shuffle]
    text = "\n".join(["ply", "format ascii 1.0", "element vertex 4", "property float x", "property float y",
                      "property float z", "property float radius", "element edge 3", "property int vertex1",
                      "property int vertex2", "end_header", *rows, *(f"{a} {b}" for a, b in edges), ""])
    (tmp_path / "adtree.ply").write_text(text)
    back = read_skeleton_ply(tmp_path / "adtree.ply")
    np.testing.assert_allclose(back.positions, stem.positions)
    np.testing.assert_allclose(back.radius, stem.radius)
    np.testing.assert_array_equal(back.parent, stem.parent)


@pytest.mark.parametrize("header, match", [
    (["element vertex 1", "property float x", "property float y", "property float z", "element face 0",
      "property list uchar int vertex_indices"], "list property"),
    (["element vertex 1", "property float x", "property float y", "property float z", "element edge 0",
      "property int vertex1", "property int vertex2"], "lacks a vertex element"),
])
def test_a_ply_without_radii_or_with_faces_is_rejected(tmp_path, header, match):
    (tmp_path / "bad.ply").write_text("\n".join(["ply", "format ascii 1.0", *header, "end_header", "0 0 0", ""]))
    with pytest.raises(QsmError, match=match):
        read_skeleton_ply(tmp_path / "bad.ply")


def test_unknown_formats_and_non_ply_files_are_rejected(tree, tmp_path):
    with pytest.raises(QsmError, match="'xml' is unknown"):
        write_skeleton_ply(tree, tmp_path / "t.ply", file_format="xml")
    (tmp_path / "t.ply").write_text("solid nothing\n")
    with pytest.raises(QsmError, match="not a PLY"):
        read_skeleton_ply(tmp_path / "t.ply")


def test_dbh_of_a_straight_cylinder_is_its_diameter():
    measures = qsm_measures(vertical([0.0, 1.0, 2.0, 3.0], [0.2] * 4))
    assert measures["dbh_m"] == pytest.approx(0.4) and measures["dbh_note"] is None


def test_dbh_is_interpolated_along_the_trunk_at_breast_height():
    measures = qsm_measures(vertical([0.0, 2.0], [0.3, 0.1]))
    assert measures["dbh_m"] == pytest.approx(2 * (0.3 - 0.2 * 1.3 / 2.0))


def test_a_tree_shorter_than_breast_height_has_no_dbh_and_says_why():
    measures = qsm_measures(vertical([0.0, 0.5, 1.0], [0.1, 0.08, 0.05]))
    assert measures["dbh_m"] is None and "below breast height 1.3 m" in measures["dbh_note"]


def test_frustum_volume_of_a_known_cone_and_cylinder():
    cone = vertical([0.0, 2.0], [0.3, 1e-9])
    assert qsm_measures(cone)["total_volume_m3"] == pytest.approx(math.pi * 0.3 ** 2 * 2.0 / 3, rel=1e-6)
    frustum = vertical([0.0, 2.0], [0.3, 0.1])
    assert segment_volumes(frustum)[1] == pytest.approx(math.pi * 2.0 * (0.09 + 0.03 + 0.01) / 3)
    cylinder = qsm_measures(vertical([0.0, 1.0, 3.0], [0.2] * 3))
    assert cylinder["trunk_volume_m3"] == pytest.approx(math.pi * 0.04 * 3.0) == cylinder["total_volume_m3"]


def test_measures_of_a_tree_are_consistent_and_json_plain(tree):
    measures = qsm_measures(tree)
    assert measures["total_length_m"] == pytest.approx(tree.total_length)
    assert 0 < measures["trunk_volume_m3"] < measures["total_volume_m3"]
    assert measures["branch_count"] == tree.n_branches - 1 and measures["height_m"] > 10
    assert all(type(v) in (float, int, type(None), str) for v in measures.values())


def test_branch_table_rows_sum_to_the_tree_and_point_at_their_parent_branches(tree):
    table = branch_table(tree)
    assert tuple(table.columns) == BRANCH_COLUMNS and len(table) == tree.n_branches
    assert table["length_m"].sum() == pytest.approx(tree.total_length, rel=1e-9)
    assert table["volume_m3"].sum() == pytest.approx(qsm_measures(tree)["total_volume_m3"], rel=1e-9)
    assert table.loc[0, "parent"] == -1 and table.loc[0, "order"] == 0
    parents = table["parent"].to_numpy()[1:]
    assert np.all((parents >= 0) & (parents < np.arange(1, len(table))))
    assert np.all(table["order"].to_numpy()[1:] > table["order"].to_numpy()[parents])
    np.testing.assert_allclose(table["base_radius_m"], tree.radius[tree.branch_starts])


def test_branch_csv_reads_back_as_the_table(tree, tmp_path):
    write_branch_csv(tree, tmp_path / "branches.csv")
    back = pd.read_csv(tmp_path / "branches.csv")
    table = branch_table(tree)
    assert list(back.columns) == list(BRANCH_COLUMNS)
    np.testing.assert_array_equal(back[["id", "parent", "order"]], table[["id", "parent", "order"]])
    np.testing.assert_allclose(back[["length_m", "base_radius_m", "volume_m3"]],
                               table[["length_m", "base_radius_m", "volume_m3"]], rtol=1e-8)


# ------------------------------------------------------------------------------ measures read off the scan's points
def stem_slice(rng, radius, arc_deg, n, centre=(0.0, 0.0), z=(1.2, 1.4), noise=0.003) -> np.ndarray:
    """(n, 3) points on the arc of a vertical stem of `radius` that a scanner on one side sees, with noise."""
    angle = rng.uniform(-np.radians(arc_deg) / 2, np.radians(arc_deg) / 2, n)
    r = radius + rng.normal(0, noise, n)
    return np.column_stack([centre[0] + r * np.cos(angle), centre[1] + r * np.sin(angle), rng.uniform(*z, n)])


def test_dbh_circle_fit_reads_a_half_scanned_stem_with_a_twig_beside_it():
    rng = np.random.default_rng(0)
    stem = stem_slice(rng, 0.25, 180, 300)
    twig = np.column_stack([rng.uniform(0.3, 0.5, 40), rng.uniform(-0.05, 0.05, 40), rng.uniform(1.25, 1.35, 40)])
    # the skeleton's trunk is far too thin: the fit reads the points, not the skeleton
    skeleton = vertical([0.0, 1.0, 2.0, 3.0], [0.12] * 4)
    measures = qsm_measures(skeleton, np.vstack([stem, twig]))
    assert measures["dbh_method"] == "circle fit" and measures["dbh_note"] is None
    assert measures["dbh_m"] == pytest.approx(0.50, rel=0.02)
    assert measures["skeleton_dbh_m"] == pytest.approx(0.24)
    assert 150 <= measures["dbh_arc_deg"] <= 180 and measures["dbh_rms_m"] < 0.01
    assert measures["dbh_points"] < len(stem[np.abs(stem[:, 2] - 1.3) <= 0.05]) + 5   # the twig is left out


@pytest.mark.parametrize("arc_deg, n, why", [(40, 300, "arc"), (360, 6, "too few")])
def test_a_short_arc_or_too_few_points_fall_back_to_the_skeleton_radius(arc_deg, n, why):
    points = stem_slice(np.random.default_rng(1), 0.2, arc_deg, n)
    measures = qsm_measures(vertical([0.0, 2.0, 3.0], [0.18] * 3), points)
    assert measures["dbh_method"] == "skeleton radius" and measures["dbh_m"] == pytest.approx(0.36)
    assert measures["dbh_points"] is None and "too few stem points" in measures["dbh_note"]


def test_crown_projection_of_a_disc_is_its_area_and_diameter_and_ignores_a_stray_return():
    rng = np.random.default_rng(2)
    r, angle = 3.0 * np.sqrt(rng.uniform(0, 1, 20000)), rng.uniform(0, 2 * np.pi, 20000)
    crown = np.column_stack([r * np.cos(angle), r * np.sin(angle), rng.uniform(2, 6, 20000)])
    stray = np.array([[20.0, 0.0, 4.0]])
    measures = qsm_measures(vertical([0.0, 1.0, 2.0], [0.1] * 3), np.vstack([crown, stray]))
    assert measures["crown_projection_area_m2"] == pytest.approx(math.pi * 9, rel=0.01)
    assert measures["crown_diameter_m"] == pytest.approx(6.0, rel=0.01)
    assert measures["scan_height_m"] == pytest.approx(crown[:, 2].max())


def test_enclosing_circle_of_known_point_sets():
    from reconstruct.scan_measures import enclosing_circle

    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0], [1.0, 1.0]])
    centre, radius = enclosing_circle(square)
    np.testing.assert_allclose(centre, [1.0, 1.0], atol=1e-9)
    assert radius == pytest.approx(math.sqrt(2))
    obtuse = np.array([[0.0, 0.0], [4.0, 0.0], [2.0, 0.5]])   # the circle on the long side, not the circumcircle
    centre, radius = enclosing_circle(obtuse)
    np.testing.assert_allclose(centre, [2.0, 0.0], atol=1e-9)
    assert radius == pytest.approx(2.0)


def test_volume_by_order_sums_to_the_woody_volume(tree):
    measures = qsm_measures(tree)
    by_order = [measures[c] for c in ORDER_VOLUME_COLUMNS]
    assert sum(by_order) == pytest.approx(measures["total_volume_m3"], rel=1e-9)
    assert by_order[0] == pytest.approx(measures["trunk_volume_m3"], rel=1e-9)
    volume = segment_volumes(tree)
    assert by_order[3] == pytest.approx(volume[tree.order >= 3].sum(), rel=1e-9)


def test_measures_without_points_leave_the_scan_keys_empty_and_keep_one_schema(tree):
    measures = qsm_measures(tree)
    assert tuple(measures) == QSM_COLUMNS
    assert measures["dbh_method"] == "skeleton radius" and measures["dbh_m"] == measures["skeleton_dbh_m"]
    assert measures["scan_height_m"] is None and measures["crown_projection_area_m2"] is None
    with pytest.raises(QsmError, match=r"shape \(4, 2\)"):
        qsm_measures(tree, np.zeros((4, 2)))


def test_qsm_csv_is_one_row_under_the_fixed_columns(tree, tmp_path):
    measures = {**qsm_measures(tree), "trunk_radius_fit_m": 0.1}
    write_qsm_csv(measures, tmp_path / "qsm.csv", source="scan.xyz")
    rows = list(csv.reader(open(tmp_path / "qsm.csv")))
    assert rows[0] == ["source", *QSM_COLUMNS, "trunk_radius_fit_m"] and len(rows) == 2
    row = dict(zip(rows[0], rows[1]))
    assert row["source"] == "scan.xyz" and row["scan_height_m"] == "" and row["dbh_method"] == "skeleton radius"
    assert float(row["total_volume_m3"]) == pytest.approx(measures["total_volume_m3"], rel=1e-8)
    assert int(row["branch_count"]) == tree.n_branches - 1
