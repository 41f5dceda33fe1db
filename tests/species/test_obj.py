"""Specification of species.obj: OBJ + MTL + PNG files of a TreeMesh, Y up, deterministic, readable by trimesh."""
import numpy as np
import pytest
import trimesh

from species.mesh import build_mesh
from species.obj import ObjError, tree_mesh_to_obj
from tests.species.skeleton_factory import fork_with_leaves, random_tree, straight_trunk


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
