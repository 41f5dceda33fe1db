"""Point clouds in: every file format to the same working-frame points, up axes, georeferenced offsets, bad input."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from reconstruct.clouds import MIN_POINTS, UP_AXES, CloudError, read_cloud, to_z_up

TREE1 = Path(__file__).resolve().parents[3] / "shared" / "data" / "pointclouds" / "tree1.xyz"


@pytest.fixture(scope="module")
def tree1():
    return np.loadtxt(TREE1)


def test_the_real_cloud_reads_upright_at_the_origin_with_its_offset(tree1):
    cloud = read_cloud(TREE1)
    assert cloud.points.dtype == np.float32 and cloud.points.shape == (len(tree1), 3)
    assert cloud.offset.dtype == np.float64
    assert cloud.points[:, 2].min() == 0.0
    np.testing.assert_allclose(cloud.height, np.ptp(tree1[:, 2]), rtol=1e-6)
    np.testing.assert_allclose(cloud.points.min(axis=0)[:2], -cloud.points.max(axis=0)[:2], atol=1e-5)
    np.testing.assert_allclose(cloud.to_scan_frame(cloud.points), tree1, atol=1e-5)


def test_georeferenced_coordinates_keep_millimetres(tree1):
    shift = np.array([4.5e6, 5.7e6, 312.0])
    far = read_cloud(tree1 + shift)
    near = read_cloud(tree1)
    np.testing.assert_allclose(far.offset - near.offset, shift, atol=1e-9)
    np.testing.assert_allclose(far.points, near.points, atol=1e-5)  # float32 of 4.5e6 would lose half a metre
    np.testing.assert_allclose(far.to_scan_frame(far.points), tree1 + shift, atol=1e-3)


@pytest.mark.parametrize("up", sorted(UP_AXES))
def test_every_up_axis_gives_the_same_upright_tree_and_no_mirror(tree1, up):
    rotation = UP_AXES[up]
    assert np.isclose(np.linalg.det(rotation), 1.0)
    stored = tree1 @ rotation  # the Z-up tree as a scanner with `up` as its up axis would store it
    np.testing.assert_allclose(to_z_up(stored, up), tree1, atol=1e-9)
    np.testing.assert_allclose(read_cloud(stored, up=up).points, read_cloud(tree1).points, atol=1e-5)


def test_text_ply_las_and_laz_files_give_the_same_points(tree1, tmp_path):
    import laspy
    import trimesh

    rgb = np.tile(np.array([[120, 90, 60]], np.uint8), (len(tree1), 1))
    np.savetxt(tmp_path / "tree.csv", np.column_stack([tree1, rgb]), delimiter=",", fmt="%.4f")
    trimesh.PointCloud(tree1, colors=rgb).export(tmp_path / "tree.ply")
    header = laspy.LasHeader(point_format=2, version="1.2")
    header.scales, header.offsets = np.full(3, 0.0001), tree1.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = tree1[:, 0], tree1[:, 1], tree1[:, 2]
    las.red, las.green, las.blue = (rgb[:, k].astype(np.uint16) * 257 for k in range(3))
    las.write(tmp_path / "tree.las")
    las.write(tmp_path / "tree.laz")
    reference = read_cloud(TREE1).points
    for name in ("tree.csv", "tree.ply", "tree.las", "tree.laz"):
        cloud = read_cloud(tmp_path / name)
        np.testing.assert_allclose(cloud.points, reference, atol=2e-4, err_msg=name)
        assert cloud.colours is not None and np.all(cloud.colours == [120, 90, 60]), name


def _one_line(call, pattern: str) -> None:
    with pytest.raises(CloudError, match=pattern) as caught:
        call()
    assert "\n" not in str(caught.value)


def test_bad_clouds_are_one_line_errors_that_say_what_is_allowed(tree1, tmp_path):
    _one_line(lambda: read_cloud(tmp_path / "none.xyz"), "does not exist")
    _one_line(lambda: read_cloud(tmp_path / "tree.obj"), r"allowed suffixes \.xyz")
    rows = tmp_path / "rows.xyz"
    rows.write_text("1 2 3\n" * 150 + "1 two 3\n")
    _one_line(lambda: read_cloud(rows), r"row 151 is '1 two 3': allowed three numbers")
    short = tmp_path / "short.xyz"
    short.write_text("1 2\n" * 150)
    _one_line(lambda: read_cloud(short), r"2 column\(s\): allowed rows of at least x y z")
    holes = tree1.copy()
    holes[[5, 9]] = np.nan
    _one_line(lambda: read_cloud(holes), r"2 point\(s\) with NaN .*first: point 6")
    _one_line(lambda: read_cloud(tree1[:MIN_POINTS - 1]), f"{MIN_POINTS - 1} points: allowed at least {MIN_POINTS}")
    flat = tree1.copy()
    flat[:, 2] = 3.0
    _one_line(lambda: read_cloud(flat), r"spans 0 m along its up axis 'z'.*is --up right")
    _one_line(lambda: read_cloud(tree1, up="up"), r"up axis 'up' is unknown: allowed z, -z, y")
    _one_line(lambda: read_cloud(np.array([["a", "b", "c"]] * 200)), "dtype")
    _one_line(lambda: read_cloud(tree1[:, :2]), rf"shape \({len(tree1)}, 2\): allowed \(N, 3\)")
    binary = tmp_path / "noise.ply"
    binary.write_bytes(b"\x00\xff" * 500)
    _one_line(lambda: read_cloud(binary), "not a readable PLY")


# Every LAS point format, each in a version that has it; the last two with extra bytes after each record.
LAS_FORMATS = [("1.2", f, 0) for f in range(4)] + [("1.3", f, 0) for f in (4, 5)] + [
    ("1.4", f, 0) for f in range(6, 11)] + [("1.2", 3, 5), ("1.4", 7, 3)]


@pytest.mark.parametrize("version, point_format, extra", LAS_FORMATS,
                         ids=[f"{v}-format{f}{'-extra' if e else ''}" for v, f, e in LAS_FORMATS])
def test_a_las_file_reads_as_laspy_reads_it(tree1, tmp_path, version, point_format, extra):
    # Uncompressed LAS is read by numpy from the header (the command's start-up): the same bytes as laspy's reading
    import laspy

    points = tree1[:300] + [1.2e5, 4.8e5, 2.0]  # georeferenced, so the offsets and scales matter
    rgb = np.random.default_rng(point_format).integers(0, 65536, (len(points), 3))
    header = laspy.LasHeader(point_format=point_format, version=version)
    if extra:
        header.add_extra_dim(laspy.ExtraBytesParams(name="spare", type=f"{extra}u1"))
    header.scales, header.offsets = np.array([0.001, 0.002, 0.0005]), points.min(axis=0) - 0.37
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    has_colour = "red" in las.point_format.dimension_names
    if has_colour:
        las.red, las.green, las.blue = (rgb[:, k].astype(np.uint16) for k in range(3))
    las.write(tmp_path / "tree.las")
    cloud = read_cloud(tmp_path / "tree.las")
    read = laspy.read(tmp_path / "tree.las")
    by_laspy = read_cloud(np.column_stack([np.asarray(read.x), np.asarray(read.y), np.asarray(read.z)]))
    assert cloud.points.tobytes() == by_laspy.points.tobytes() and cloud.offset.tobytes() == by_laspy.offset.tobytes()
    if has_colour:
        assert np.array_equal(cloud.colours, np.round(rgb / 257.0).astype(np.uint8))
    else:
        assert cloud.colours is None


def test_a_las_file_shorter_than_its_header_says_is_a_one_line_error(tree1, tmp_path):
    import laspy

    las = laspy.LasData(laspy.LasHeader(point_format=3, version="1.2"))
    las.x, las.y, las.z = tree1[:, 0], tree1[:, 1], tree1[:, 2]
    las.write(tmp_path / "tree.las")
    cut = tmp_path / "cut.las"
    cut.write_bytes((tmp_path / "tree.las").read_bytes()[:-1000])
    _one_line(lambda: read_cloud(cut), "is not a readable LAS/LAZ file")
