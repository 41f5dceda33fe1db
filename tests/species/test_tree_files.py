"""Grown trees as files: every preset's GLB passes the Khronos validator and round-trips through trimesh, and
`species.meshing.write_tree` writes a tree's GLB, or its OBJ with the MTL and textures, where it is told."""
import dataclasses
import io

import numpy as np
import pytest
import trimesh

import species
from species.errors import PathError
from species.meshing import write_tree
from tests.gltf_validator import assert_valid_glb

PRESETS = [p.name for p in species.list_presets()]


def grown_mesh(name: str, seed: int = 0):
    params = species.sample(name, np.random.default_rng(seed))
    return species.build_mesh(species.grow(params, species.rng_for(params)), params)


@pytest.mark.parametrize("name", PRESETS)
def test_preset_glb_passes_the_khronos_validator(name, tmp_path):
    mesh = grown_mesh(name)
    assert_valid_glb(mesh.to_glb(), tmp_path, f"{name}.glb")


@pytest.mark.parametrize("name", ["maple", "pine"])
def test_glb_round_trip_keeps_counts(name):
    mesh = grown_mesh(name, seed=1)
    scene = trimesh.load(io.BytesIO(mesh.to_glb()), file_type="glb")
    counts = {g.metadata.get("name", k): (len(g.vertices), len(g.faces)) for k, g in scene.geometry.items()}
    assert sum(v for v, _ in counts.values()) == mesh.n_vertices
    assert sum(f for _, f in counts.values()) == mesh.n_faces


def test_bark_has_no_nan_no_degenerate_faces_and_sits_on_the_ground():
    mesh = grown_mesh("cherry")
    bark = mesh.bark
    assert np.isfinite(bark.vertices).all()
    assert bark.face_areas.min() > 0
    assert bark.vertices[:, 2].min() == pytest.approx(0.0, abs=0.02)


@pytest.fixture(scope="module")
def maple():
    return dataclasses.replace(grown_mesh("maple"), name="maple")


def test_write_tree_puts_the_glb_bytes_in_the_named_file_making_its_folders(maple, tmp_path):
    path = tmp_path / "made" / "here" / "tree.glb"
    assert write_tree(maple, path, "glb") == [path]
    assert path.read_bytes() == maple.to_glb()


def test_write_tree_puts_an_obj_beside_its_mtl_and_textures_the_obj_first(maple, tmp_path):
    files = write_tree(maple, tmp_path / "maple.obj", "obj")
    expected = maple.to_obj()
    assert files[0] == tmp_path / "maple.obj" and sorted(p.name for p in files) == sorted(expected)
    assert all((tmp_path / name).read_bytes() == data for name, data in expected.items())


def test_write_tree_names_the_path_it_cannot_write(maple, tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(PathError, match="cannot write .*a_file/tree.glb"):
        write_tree(maple, blocker / "tree.glb", "glb")
