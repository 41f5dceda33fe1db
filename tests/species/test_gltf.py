"""Specification of species.meshing.gltf: GLB bytes of a TreeMesh, valid glTF 2.0, Y up, deterministic; the
GlbWriter every GLB is written with."""
import io
import struct

import numpy as np
import pytest
import trimesh

from species.meshing.gltf import (CLAMP_TO_EDGE, Z_UP_TO_Y_UP, GlbBuffer, GlbError, GlbWriter, node_matrix,
                                  read_accessor, read_glb_chunks, read_glb_json, tree_mesh_to_glb, z_up_to_y_up)
from species.meshing.tubes_and_cards import build_mesh
from species.tree_mesh import MeshError, MeshPart, TreeMesh
from tests.gltf_validator import assert_valid_glb
from fixtures.skeletons import fork_with_leaves, random_tree, straight_trunk


@pytest.fixture(scope="module")
def fork_mesh():
    return build_mesh(fork_with_leaves(), {"name": "fork"})


@pytest.fixture(scope="module")
def fork_glb(fork_mesh):
    return fork_mesh.to_glb()


def test_fork_glb_passes_the_khronos_validator(fork_mesh, fork_glb, tmp_path):
    report = assert_valid_glb(fork_glb, tmp_path)
    assert report["info"]["totalTriangleCount"] == fork_mesh.n_faces and report["info"]["drawCallCount"] == 2


def test_random_tree_glb_passes_the_khronos_validator_without_warnings(tmp_path):
    mesh = build_mesh(random_tree(np.random.default_rng(1), n_nodes=800, n_leaves=1500))
    report = assert_valid_glb(mesh.to_glb(), tmp_path)
    assert report["issues"]["numWarnings"] == 0
    assert report["info"]["totalTriangleCount"] == mesh.n_faces


def test_leafless_tree_omits_the_leaves_mesh_and_stays_valid(tmp_path):
    data = build_mesh(straight_trunk()).to_glb()
    document = read_glb_json(data)
    assert [m["name"] for m in document["meshes"]] == ["bark"]
    assert_valid_glb(data, tmp_path)


def test_same_tree_gives_identical_bytes():
    skeleton = random_tree(np.random.default_rng(5), n_nodes=300, n_leaves=400)
    assert build_mesh(skeleton).to_glb() == build_mesh(skeleton).to_glb()


def test_scene_has_a_root_named_after_the_tree_with_bark_and_leaves(fork_glb):
    document = read_glb_json(fork_glb)
    root = document["nodes"][document["scenes"][document["scene"]]["nodes"][0]]
    assert root["name"] == "fork"
    assert [document["nodes"][i]["name"] for i in root["children"]] == ["bark", "leaves"]


def test_materials_are_textured_pbr_with_masked_double_sided_leaves(fork_glb):
    document = read_glb_json(fork_glb)
    bark, leaves = document["materials"]
    assert bark["pbrMetallicRoughness"]["metallicFactor"] == 0 and bark["pbrMetallicRoughness"]["roughnessFactor"] == 0.9
    assert leaves["alphaMode"] == "MASK" and leaves["alphaCutoff"] == 0.5 and leaves["doubleSided"] is True
    assert all(image["mimeType"] == "image/png" for image in document["images"])
    bark_sampler = document["samplers"][document["textures"][bark["pbrMetallicRoughness"]["baseColorTexture"]["index"]]["sampler"]]
    assert bark_sampler["wrapS"] == bark_sampler["wrapT"] == 10497  # REPEAT


def test_chunks_and_buffer_views_are_four_byte_aligned(fork_glb):
    document, binary = read_glb_chunks(fork_glb)
    json_length = struct.unpack_from("<I", fork_glb, 12)[0]
    assert len(fork_glb) % 4 == 0 and json_length % 4 == 0 and len(binary) % 4 == 0
    assert all(view["byteOffset"] % 4 == 0 for view in document["bufferViews"])


def test_world_z_becomes_gltf_y(fork_mesh, fork_glb):
    document, binary = read_glb_chunks(fork_glb)
    position = document["meshes"][0]["primitives"][0]["attributes"]["POSITION"]
    gltf = read_accessor(document, binary, position)
    world = fork_mesh.bark.vertices
    np.testing.assert_array_equal(gltf[:, 1], world[:, 2])   # height h at world z is glTF y
    np.testing.assert_array_equal(gltf[:, 2], -world[:, 1])
    np.testing.assert_array_equal(gltf[:, 0], world[:, 0])


def test_texture_v_is_flipped_for_gltf(fork_mesh, fork_glb):
    document, binary = read_glb_chunks(fork_glb)
    texcoord = document["meshes"][1]["primitives"][0]["attributes"]["TEXCOORD_0"]
    np.testing.assert_allclose(read_accessor(document, binary, texcoord)[:, 1], 1 - fork_mesh.leaves.uvs[:, 1])


def test_trimesh_reads_back_the_same_counts_and_names(fork_mesh, fork_glb):
    scene = trimesh.load(io.BytesIO(fork_glb), file_type="glb")
    assert set(scene.geometry) == {"bark", "leaves"}
    for name, part in (("bark", fork_mesh.bark), ("leaves", fork_mesh.leaves)):
        assert len(scene.geometry[name].vertices) == part.n_vertices
        assert len(scene.geometry[name].faces) == part.n_faces


def test_large_meshes_use_32_bit_indices():
    mesh = build_mesh(random_tree(np.random.default_rng(2), n_nodes=400, n_leaves=17000))
    document = read_glb_json(mesh.to_glb())
    leaves_indices = document["meshes"][1]["primitives"][0]["indices"]
    assert mesh.leaves.n_vertices > 65535 and document["accessors"][leaves_indices]["componentType"] == 5125


def test_a_mesh_part_with_out_of_range_faces_is_rejected():
    with pytest.raises(MeshError, match="face indices"):
        MeshPart(np.zeros((3, 3)), [[0, 1, 3]], np.tile([0, 0, 1.0], (3, 1)), np.zeros((3, 2)))


def test_non_tree_mesh_input_is_rejected():
    with pytest.raises(GlbError, match="TreeMesh"):
        tree_mesh_to_glb(fork_with_leaves())


def test_reading_bytes_that_are_not_glb_is_rejected(fork_glb):
    with pytest.raises(GlbError, match="glTF 2.0"):
        read_glb_json(b"PK\x03\x04" + fork_glb[4:])
    with pytest.raises(GlbError, match="bytes"):
        read_glb_json(fork_glb[:-4])


def test_empty_tree_mesh_is_still_a_valid_file(tmp_path):
    empty = TreeMesh(MeshPart.empty(), MeshPart.empty(), name="nothing")
    assert_valid_glb(empty.to_glb(), tmp_path)


def test_z_up_to_y_up_is_the_rotation_matrix_applied():
    vectors = np.random.default_rng(3).normal(size=(50, 3)).astype(np.float32)
    np.testing.assert_array_equal(z_up_to_y_up(vectors), (vectors.astype(np.float64) @ Z_UP_TO_Y_UP.T).astype(np.float32))
    assert np.allclose(Z_UP_TO_Y_UP @ Z_UP_TO_Y_UP.T, np.eye(3)) and np.linalg.det(Z_UP_TO_Y_UP) == 1.0
    np.testing.assert_array_equal(Z_UP_TO_Y_UP @ [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])  # world up is glTF's +y


def _written(keep_bytes: bool) -> GlbWriter:
    """A writer holding one textured triangle mesh with an extra attribute and instance-like data."""
    writer = GlbWriter(keep_bytes)
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    attributes, indices = writer.triangles(vertices, np.tile([0.0, -1.0, 0.0], (3, 1)),
                                           [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], [[0, 1, 2]],
                                           {"_WIND": (np.ones((3, 4)), "VEC4")})
    material = writer.material({"name": "m", "pbrMetallicRoughness": {
        "baseColorTexture": {"index": writer.texture("t", b"\x89PNG not really", CLAMP_TO_EDGE)}}})
    mesh = writer.mesh("tri", {"attributes": attributes, "indices": indices, "material": material, "mode": 4})
    writer.node({"name": "tri", "mesh": mesh, "extras": {"scale": writer.floats(np.ones((5, 3)), "VEC3", None)}})
    return writer


HEAD = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}]}


def test_a_written_document_reads_back_attribute_for_attribute():
    data = _written(True).to_glb(HEAD)
    document, binary = read_glb_chunks(data)
    attributes = document["meshes"][0]["primitives"][0]["attributes"]
    assert list(attributes) == ["POSITION", "NORMAL", "TEXCOORD_0", "_WIND"]
    np.testing.assert_array_equal(read_accessor(document, binary, attributes["POSITION"]),
                                  [[0, 0, 0], [1, 0, 0], [0, 1, 0]])  # world z is glTF y
    np.testing.assert_array_equal(read_accessor(document, binary, attributes["TEXCOORD_0"])[:, 1], [1, 1, 0])
    assert document["accessors"][attributes["POSITION"]]["max"] == [1.0, 1.0, 0.0]
    assert document["accessors"][document["meshes"][0]["primitives"][0]["indices"]]["componentType"] == 5123
    image = document["images"][0]
    view = document["bufferViews"][image["bufferView"]]
    assert binary[view["byteOffset"]:view["byteOffset"] + view["byteLength"]] == b"\x89PNG not really"
    assert "target" not in document["bufferViews"][document["accessors"][-1]["bufferView"]]


def test_a_writer_that_keeps_no_bytes_counts_the_exact_file_length():
    counted = _written(False)
    assert counted.glb_length(HEAD) == len(_written(True).to_glb(HEAD)) == _written(True).glb_length(HEAD)
    with pytest.raises(TypeError, match="keep_bytes"):
        counted.buffer.tobytes()


def test_buffer_views_are_padded_to_four_bytes():
    buffer = GlbBuffer()
    buffer.view(b"abc")
    buffer.view(b"defgh", target=34963)
    assert buffer.tobytes() == b"abc\0defgh\0\0\0" and buffer.size == 12
    assert [(v["byteOffset"], v["byteLength"]) for v in buffer.views] == [(0, 3), (4, 5)]


# --------------------------------------------------------------- transform and extras (issue 24 outputs)
def _scan_transform() -> np.ndarray:
    """A rotation of 30 degrees about world z, scale 2, and a georeferenced-size translation (Z up, metres)."""
    angle = np.radians(30.0)
    transform = np.eye(4)
    transform[:3, :3] = 2.0 * np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0],
                                        [0, 0, 1]])
    transform[:3, 3] = [512345.25, -4210987.5, 312.0]
    return transform


def test_a_transform_puts_each_point_where_it_maps_in_our_frame_after_reading_back(fork_mesh):
    transform = _scan_transform()
    document, binary = read_glb_chunks(fork_mesh.to_glb(transform=transform))
    root = document["nodes"][document["scenes"][0]["nodes"][0]]
    matrix = np.array(root["matrix"]).reshape(4, 4).T  # glTF stores column-major
    gltf = read_accessor(document, binary, document["meshes"][0]["primitives"][0]["attributes"]["POSITION"])
    placed_gltf = gltf.astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
    placed_world = placed_gltf @ Z_UP_TO_Y_UP  # back from glTF's Y up to our Z up
    expected = fork_mesh.bark.vertices.astype(np.float64) @ transform[:3, :3].T + transform[:3, 3]
    np.testing.assert_allclose(placed_world, expected, rtol=0, atol=1e-6)


def test_extras_are_stored_on_the_root_node_and_the_file_validates(fork_mesh, tmp_path):
    extras = {"frame": "scan", "offset_m": [512345.25, -4210987.5, 312.0], "dbh_m": 0.31, "note": None}
    data = fork_mesh.to_glb(transform=_scan_transform(), extras=extras)
    document = read_glb_json(data)
    root = document["nodes"][document["scenes"][0]["nodes"][0]]
    assert root["extras"] == extras and root["name"] == "fork"
    assert [document["nodes"][i]["name"] for i in root["children"]] == ["bark", "leaves"]
    assert_valid_glb(data, tmp_path)


def test_no_arguments_and_an_identity_transform_write_the_same_bytes_as_before(fork_mesh, fork_glb):
    assert tree_mesh_to_glb(fork_mesh) == fork_glb == fork_mesh.to_glb(None, None)
    assert fork_mesh.to_glb(transform=np.eye(4)) == fork_glb
    assert "matrix" not in read_glb_json(fork_glb)["nodes"][0] and "extras" not in read_glb_json(fork_glb)["nodes"][0]


def test_node_matrix_is_the_transform_conjugated_into_y_up():
    transform = _scan_transform()
    turn = np.eye(4)
    turn[:3, :3] = Z_UP_TO_Y_UP
    np.testing.assert_array_equal(np.array(node_matrix(transform)).reshape(4, 4).T, turn @ transform @ turn.T)
    assert node_matrix(np.eye(4)) is None


@pytest.mark.parametrize("transform, match", [
    (np.eye(3), "shape"),
    ([[1, 0, 0, np.nan], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "NaN"),
    ([[1, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], "rotation times a positive scale"),
    (np.diag([1.0, -1.0, 1.0, 1.0]), "determinant"),
    ([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]], "bottom row"),
    ("up", "not numeric"),
])
def test_a_transform_that_is_not_a_trs_matrix_is_rejected(fork_mesh, transform, match):
    with pytest.raises(GlbError, match=match):
        fork_mesh.to_glb(transform=transform)


@pytest.mark.parametrize("extras", [["frame"], {1: "x"}, {"dbh": float("nan")}, {"when": object()}])
def test_extras_that_are_not_a_json_object_are_rejected(fork_mesh, extras):
    with pytest.raises(GlbError, match="extras"):
        fork_mesh.to_glb(extras=extras)
