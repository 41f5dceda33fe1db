"""Specification of species.meshing.tree_files: a TreeMesh written as a GLB file, or as OBJ + MTL + textures."""
import pytest

from species.errors import PathError
from species.meshing import build_mesh, write_tree
from tests.species.skeleton_factory import fork_with_leaves


@pytest.fixture(scope="module")
def fork_mesh():
    return build_mesh(fork_with_leaves(), {"name": "fork"})


def test_a_glb_is_the_meshs_bytes_in_the_named_file_its_folders_made(fork_mesh, tmp_path):
    path = tmp_path / "made" / "here" / "tree.glb"
    assert write_tree(fork_mesh, path, "glb") == [path]
    assert path.read_bytes() == fork_mesh.to_glb()


def test_an_obj_is_its_files_beside_the_named_one_the_obj_first(fork_mesh, tmp_path):
    files = write_tree(fork_mesh, tmp_path / "fork.obj", "obj")
    assert files[0] == tmp_path / "fork.obj"
    expected = fork_mesh.to_obj()
    assert sorted(p.name for p in files) == sorted(expected)
    assert all((tmp_path / name).read_bytes() == data for name, data in expected.items())


def test_a_file_error_names_the_path(fork_mesh, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(PathError, match="cannot write .*a_file/tree.glb"):
        write_tree(fork_mesh, blocker / "tree.glb", "glb")
