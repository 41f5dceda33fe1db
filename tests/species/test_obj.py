"""Specification of species.meshing.obj: OBJ + MTL + PNG files of a TreeMesh, Y up, deterministic, readable by trimesh.

Also of species.meshing.ascii_numbers, its vectorized number text: byte-identical to Python's "%.6f" and "%d".
"""
import dataclasses

import numpy as np
import pytest
import trimesh

from species.meshing.ascii_numbers import AsciiNumberError, fixed6_rows, int_rows
from species.meshing.gltf import z_up_to_y_up
from species.meshing.tubes_and_cards import build_mesh
from species.meshing.obj import ObjError, tree_mesh_to_obj
from fixtures.skeletons import fork_with_leaves, random_tree, straight_trunk


@pytest.fixture(scope="module")
def fork_mesh():
    return build_mesh(fork_with_leaves(), {"name": "fork"})


def _write(files: dict, folder):
    for name, data in files.items():
        (folder / name).write_bytes(data)


def test_files_are_the_obj_its_mtl_and_two_textures(fork_mesh):
    assert sorted(fork_mesh.to_obj()) == ["fork.mtl", "fork.obj", "fork_bark.png", "fork_leaf.png"]


def test_mtl_names_textures_and_leaf_alpha(fork_mesh):
    mtl = fork_mesh.to_obj()["fork.mtl"].decode()
    assert "newmtl bark" in mtl and "map_Kd fork_bark.png" in mtl
    assert "newmtl leaves" in mtl and "map_Kd fork_leaf.png" in mtl and "map_d fork_leaf.png" in mtl


def test_trimesh_reads_back_the_same_counts_per_object(fork_mesh, tmp_path):
    _write(fork_mesh.to_obj(), tmp_path)
    scene = trimesh.load(tmp_path / "fork.obj", process=False)
    assert set(scene.geometry) == {"bark", "leaves"}
    for name, part in (("bark", fork_mesh.bark), ("leaves", fork_mesh.leaves)):
        assert len(scene.geometry[name].vertices) == part.n_vertices
        assert len(scene.geometry[name].faces) == part.n_faces


def test_positions_are_converted_to_y_up(fork_mesh, tmp_path):
    _write(fork_mesh.to_obj(), tmp_path)
    bark = trimesh.load(tmp_path / "fork.obj", process=False).geometry["bark"]
    world = fork_mesh.bark.vertices.astype(np.float64)
    expected = np.stack([world[:, 0], world[:, 2], -world[:, 1]], axis=1)
    np.testing.assert_allclose(np.sort(bark.vertices, axis=0), np.sort(expected, axis=0), atol=2e-6)


def test_same_tree_gives_identical_files():
    skeleton = random_tree(np.random.default_rng(4), n_nodes=300, n_leaves=300)
    assert build_mesh(skeleton).to_obj() == build_mesh(skeleton).to_obj()


def test_leafless_tree_has_no_leaves_object(tmp_path):
    text = build_mesh(straight_trunk(), {"name": "pole"}).to_obj()["pole.obj"].decode()
    assert "o bark" in text and "o leaves" not in text


def test_faces_index_their_own_vertices_one_based(fork_mesh):
    text = fork_mesh.to_obj()["fork.obj"].decode().splitlines()
    n_vertices = sum(line.startswith("v ") for line in text)
    indices = np.array([int(c.split("/")[0]) for line in text if line.startswith("f ") for c in line.split()[1:]])
    assert n_vertices == fork_mesh.n_vertices and indices.min() == 1 and indices.max() == n_vertices


def test_a_name_that_is_not_a_file_stem_is_rejected():
    mesh = build_mesh(straight_trunk(), {"name": "../evil tree"})
    with pytest.raises(ObjError, match="evil"):
        tree_mesh_to_obj(mesh)


def _percent_rows(template: str, values: np.ndarray) -> bytes:
    """The reference: Python's own %-formatting of every row (what the writer did before vectorizing)."""
    return ((template * len(values)) % tuple(values.ravel().tolist())).encode("ascii")


def _awkward_floats(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n,) float64 of every kind "%.6f" can trip on: small and large magnitudes, both signs, zeros,
    negatives that round to zero, exact binary ties at the 7th decimal and values one ulp either side of one."""
    near_ties = (rng.integers(-10**7, 10**7, n) + 0.5) / 1e6
    return np.concatenate([
        rng.normal(0.0, 3.0, n), rng.normal(0.0, 1e5, n), rng.uniform(-1e9, 1e9, n) * (1 - 1e-12),
        (rng.integers(-2**20, 2**20, n) * 2 + 1) / 128.0,  # exact ties, e.g. 0.0078125
        near_ties, np.nextafter(near_ties, np.inf), np.nextafter(near_ties, -np.inf),
        [0.0, -0.0, -1e-9, 4e-7, -4e-7, 5e-7, -5e-7, 1e-300, 999999.9999995, -999999999.9999994],
    ])


def test_fixed6_rows_equal_percent_format_on_awkward_values():
    values = _awkward_floats(np.random.default_rng(0), 20_000)[:70_002].reshape(-1, 3)
    assert fixed6_rows("v", values) == _percent_rows("v %.6f %.6f %.6f\n", values)


def test_fixed6_rows_of_float32_equal_percent_format_of_its_float64():
    values = _awkward_floats(np.random.default_rng(1), 20_000).astype(np.float32)
    values = values[np.abs(values) < 1e8][:60_000].reshape(-1, 2)
    assert fixed6_rows("vt", values) == _percent_rows("vt %.6f %.6f\n", values.astype(np.float64))


def test_fixed6_rows_keep_the_sign_of_negatives_that_round_to_zero():
    assert fixed6_rows("vn", np.array([[-0.0, -4e-7, 4e-7]])) == b"vn -0.000000 -0.000000 0.000000\n"


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf, 1e9, -2.5e12])
def test_fixed6_rows_reject_non_finite_and_too_large_values_by_name(bad):
    values = np.array([[1.0, 2.0], [3.0, bad]])
    with pytest.raises(AsciiNumberError, match=rf"value {bad!r} \(row 1, column 1\).*\|v\| < 1,000,000,000"):
        fixed6_rows("vt", values)


def test_int_rows_equal_percent_d_with_separators():
    rng = np.random.default_rng(2)
    values = np.concatenate([rng.integers(-10**18 + 1, 10**18, (3000, 9)), rng.integers(-1200, 1200, (3000, 9)),
                             [[0, -1, 9, 10, 99, 100, -999, 1000, 10**18 - 1]]])
    assert int_rows("f", values, " // // //") == _percent_rows("f %d/%d/%d %d/%d/%d %d/%d/%d\n", values)


def test_int_rows_of_mesh_indices_equal_percent_d():
    """Indices spanning a range no wider than their count take the spell-once-and-gather path."""
    faces = np.random.default_rng(3).integers(1, 150_001, (100_000, 3)).repeat(3, axis=1)
    assert int_rows("f", faces, " // // //") == _percent_rows("f %d/%d/%d %d/%d/%d %d/%d/%d\n", faces)


def test_int_rows_reject_magnitudes_beyond_int64_digits():
    with pytest.raises(AsciiNumberError, match=r"value 1000000000000000000 \(row 0, column 1\)"):
        int_rows("l", np.array([[5, 10**18]]), "  ")


def test_empty_rows_give_no_text():
    assert fixed6_rows("v", np.zeros((0, 3))) == b"" and int_rows("f", np.zeros((0, 3), int), "   ") == b""


def test_obj_text_equals_percent_formatting_of_the_mesh(fork_mesh):
    """Byte for byte what a plain %-format writer gives: header, mtllib, then o/v/vt/vn/usemtl/s/f per object."""
    expected, first_index = [b"# treefarm tree fork: metres, Y up (converted from the farm's Z up)\n"
                             b"mtllib fork.mtl\n"], 1
    for name, part in (("bark", fork_mesh.bark), ("leaves", fork_mesh.leaves)):
        corners = (part.faces.astype(np.int64) + first_index).repeat(3, axis=1)
        expected += [f"o {name}\n".encode(),
                     _percent_rows("v %.6f %.6f %.6f\n", z_up_to_y_up(part.vertices).astype(np.float64)),
                     _percent_rows("vt %.6f %.6f\n", part.uvs.astype(np.float64)),
                     _percent_rows("vn %.6f %.6f %.6f\n", z_up_to_y_up(part.normals).astype(np.float64)),
                     f"usemtl {name}\ns 1\n".encode(),
                     _percent_rows("f %d/%d/%d %d/%d/%d %d/%d/%d\n", corners)]
        first_index += part.n_vertices
    assert fork_mesh.to_obj()["fork.obj"] == b"".join(expected)


def test_trimesh_reads_back_positions_within_a_micrometre(tmp_path):
    mesh = build_mesh(random_tree(np.random.default_rng(5), n_nodes=200, n_leaves=100), {"name": "tree"})
    _write(mesh.to_obj(), tmp_path)
    leaves = trimesh.load(tmp_path / "tree.obj", process=False).geometry["leaves"]
    np.testing.assert_allclose(leaves.vertices, z_up_to_y_up(mesh.leaves.vertices), rtol=0, atol=1e-6)


def test_a_vertex_beyond_the_writable_range_raises_obj_error_naming_it(fork_mesh):
    far = dataclasses.replace(fork_mesh.bark, vertices=fork_mesh.bark.vertices + np.float32([0, 0, 2e9]))
    with pytest.raises(ObjError, match=r"bark .*value 2000000\d+\.\d+ .*allowed finite numbers"):
        tree_mesh_to_obj(dataclasses.replace(fork_mesh, bark=far))
