"""Blender outputs of the asset library: FBX files read back by Blender's importer, `.blend` libraries read back
by the worker (assets, previews, tags, catalogs), the catalog file (`farm.library.blender_catalog`), and bad
input.

Blender runs for real (`.venv-blender`, built by `make env`); without it every Blender test fails with that hint.
"""
from __future__ import annotations

import struct

import numpy as np
import pytest

import species
from farm.library.blender_catalog import (CATALOG_FILE, catalog_uuid, inspect_blender_library, read_catalog_file,
                                          write_blender_library, write_catalog_file)
from renderers.blender import BlenderError
from renderers.blender_assets import export_fbx, export_fbx_batch, inspect_blend, read_fbx, write_asset_library
from renderers.blender_worker.blend_bytes import make_deterministic
from species.meshing.gltf import ELEMENT_ARRAY_BUFFER, GlbWriter

PRESET = "sc_young_sapling"  # a small real tree: about 2,000 triangles, grown in a tenth of a second
PREVIEW_RGB = (200, 40, 90)
LOD_TRIANGLES = {"LOD0": 1280 + 64, "LOD1": 80}


N_LEAVES = 30


def _instanced_glb() -> bytes:
    """A GLB laid out like the library's asset GLBs: scene root X_LOD0 with X_LOD0_bark (a box, 12 triangles, with
    _WIND and _WIND_PIVOT attributes) and
    X_LOD0_leaves (one 2-triangle card drawn N_LEAVES times with EXT_mesh_gpu_instancing); X_LOD1 (one triangle)
    outside the scene, as MSFT_lod keeps coarser levels. Written Y up, as given (no normals, UVs or materials)."""
    writer = GlbWriter()

    def mesh(name: str, vertices, faces, wind: bool = False) -> int:
        vertices = np.array(vertices, np.float32)
        attributes = {"POSITION": writer.floats(vertices, "VEC3", with_bounds=True)}
        if wind:  # the library's wind layout: two custom attributes of different widths
            attributes["_WIND"] = writer.floats(np.zeros((len(vertices), 4)), "VEC4")
            attributes["_WIND_PIVOT"] = writer.floats(np.zeros((len(vertices), 3)), "VEC3")
        indices = writer.buffer.accessor(np.array(faces, np.uint32).reshape(-1), "SCALAR", ELEMENT_ARRAY_BUFFER)
        return writer.mesh(name, {"attributes": attributes, "indices": indices})

    box = [[x, y, z] for x in (-0.2, 0.2) for y in (0.0, 2.0) for z in (-0.2, 0.2)]
    box_faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                 [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    card = [[-0.1, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.2, 0.0], [-0.1, 0.2, 0.0]]
    offsets = np.random.default_rng(0).uniform(-1, 1, (N_LEAVES, 3)) + [0, 2, 0]
    bark, leaf, lod1 = (mesh("box", box, box_faces, wind=True), mesh("card", card, [[0, 1, 2], [0, 2, 3]]),
                        mesh("triangle", card[:3], [[0, 1, 2]]))
    instancing = {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": writer.floats(offsets, "VEC3", None)}}}
    for entry in ({"name": "X_LOD0", "children": [1, 2]}, {"name": "X_LOD0_bark", "mesh": bark},
                  {"name": "X_LOD0_leaves", "mesh": leaf, "extensions": instancing},
                  {"name": "X_LOD1", "children": [4]}, {"name": "X_LOD1_bark", "mesh": lod1}):
        writer.node(entry)
    return writer.to_glb({"asset": {"version": "2.0"}, "extensionsUsed": ["EXT_mesh_gpu_instancing"], "scene": 0,
                          "scenes": [{"nodes": [0]}]})


# ------------------------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def tree(tmp_path_factory):
    """(TreeMesh, GLB path) of a grown tree."""
    params = species.sample(PRESET, np.random.default_rng(5))
    mesh = species.build_mesh(species.grow(params, species.rng_for(params)), params)
    path = tmp_path_factory.mktemp("glb") / "sapling.glb"
    path.write_bytes(mesh.to_glb())
    return mesh, path


@pytest.fixture(scope="module")
def lods_glb(tmp_path_factory):
    """A GLB made by trimesh with two LOD nodes: LOD0 (crown 1,280 + trunk 64 triangles), LOD1 (crown 80)."""
    import trimesh

    scene = trimesh.Scene()
    for lod in LOD_TRIANGLES:
        scene.graph.update(frame_to=lod, frame_from=scene.graph.base_frame)
    up = trimesh.transformations.translation_matrix
    scene.add_geometry(trimesh.creation.icosphere(subdivisions=3), node_name="LOD0_crown", geom_name="crown0",
                       parent_node_name="LOD0", transform=up([0, 3, 0]))
    scene.add_geometry(trimesh.creation.cylinder(radius=0.2, height=2, sections=16), node_name="LOD0_trunk",
                       geom_name="trunk0", parent_node_name="LOD0", transform=up([0, 1, 0]))
    scene.add_geometry(trimesh.creation.icosphere(subdivisions=1), node_name="LOD1_crown", geom_name="crown1",
                       parent_node_name="LOD1", transform=up([0, 3, 0]))
    path = tmp_path_factory.mktemp("glb") / "lods.glb"
    path.write_bytes(scene.export(file_type="glb"))
    return path


@pytest.fixture(scope="module")
def instanced_glb(tmp_path_factory):
    path = tmp_path_factory.mktemp("glb") / "instanced.glb"
    path.write_bytes(_instanced_glb())
    return path


@pytest.fixture(scope="module")
def fbx_batch(tree, lods_glb, instanced_glb, tmp_path_factory):
    """One Blender run: the tree, LOD0 and LOD1 of the trimesh GLB, X_LOD0 and X_LOD1 of the instanced GLB."""
    out = tmp_path_factory.mktemp("fbx")
    jobs = [{"glb": tree[1], "fbx": out / "sapling.fbx", "name": "sapling_0001"},
            {"glb": lods_glb, "fbx": out / "lod0.fbx", "node": "LOD0"},
            {"glb": lods_glb, "fbx": out / "lod1.fbx", "node": "LOD1"},
            {"glb": instanced_glb, "fbx": out / "x_lod0.fbx", "node": "X_LOD0"},
            {"glb": instanced_glb, "fbx": out / "x_lod1.fbx", "node": "X_LOD1"}]
    return export_fbx_batch(jobs)


@pytest.fixture(scope="module")
def tree_fbx_read_back(fbx_batch):
    return read_fbx(fbx_batch[0]["fbx"])


@pytest.fixture(scope="module")
def library_assets(tree, lods_glb, instanced_glb, tmp_path_factory):
    """Four assets for a .blend: a 512 px preview given; previews drawn; LOD nodes."""
    from PIL import Image

    preview = tmp_path_factory.mktemp("preview") / "preview.png"
    Image.fromarray(np.broadcast_to(np.array(PREVIEW_RGB, np.uint8), (512, 512, 3)).copy()).save(preview)
    assets = [
        {"id": "sapling_0001", "glb_path": tree[1], "preview_png": preview, "tags": ["sapling", "broadleaf"],
         "catalog_path": "Trees/Sapling", "description": "a young sapling", "properties": {"seed": 5}},
        {"id": "sapling_0002", "glb_path": tree[1], "tags": ["sapling"], "catalog_path": "Trees/Sapling"},
        {"id": "boxes_lod0", "glb_path": lods_glb, "node": "LOD0", "tags": ["test"], "catalog_path": "Tests/Boxes"},
        {"id": "X", "glb_path": instanced_glb, "node": "X_LOD0", "tags": ["test"], "catalog_path": "Tests/Boxes"},
    ]
    return assets


@pytest.fixture(scope="module")
def library(library_assets, tmp_path_factory):
    """The .blend of `library_assets` and its inspection."""
    written = write_blender_library(library_assets, tmp_path_factory.mktemp("library") / "saplings.blend")
    read = inspect_blender_library(written["blend"])
    return written, {row["name"]: row for row in read["assets"]}, read


# ------------------------------------------------------------------------------------------- FBX
def test_fbx_reimports_with_the_triangle_count_of_each_part(tree, tree_fbx_read_back):
    mesh, _ = tree
    counts = {row["part"]: row["triangles"] for row in tree_fbx_read_back["objects"]}
    assert counts == {"bark": len(mesh.bark.faces), "leaves": len(mesh.leaves.faces)}


def test_fbx_export_reports_the_triangles_it_wrote(fbx_batch, tree_fbx_read_back):
    assert fbx_batch[0]["triangles_per_object"] == {r["name"]: r["triangles"] for r in tree_fbx_read_back["objects"]}


def test_fbx_names_the_tree_after_the_given_name(tree_fbx_read_back):
    assert sorted(r["name"] for r in tree_fbx_read_back["objects"]) == ["sapling_0001_bark", "sapling_0001_leaves"]


def test_fbx_keeps_metres_and_z_up(tree, tree_fbx_read_back):
    mesh, _ = tree
    vertices = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    expected = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    np.testing.assert_allclose(np.array(tree_fbx_read_back["bounds"]), expected, atol=1e-3)


def _fbx_double_property(data: bytes, name: bytes) -> float:
    """The value of a binary FBX "P" property record of type double: name, type, label, flags, then D <value>."""
    at = data.index(b"S" + struct.pack("<I", len(name)) + name) + 5 + len(name)
    for _ in range(3):  # type name, label and flags: three more strings
        assert data[at:at + 1] == b"S"
        at += 5 + struct.unpack("<I", data[at + 1:at + 5])[0]
    assert data[at:at + 1] == b"D"
    return struct.unpack("<d", data[at + 1:at + 9])[0]


def _fbx_int_property(data: bytes, name: bytes) -> int:
    at = data.index(b"S" + struct.pack("<I", len(name)) + name) + 5 + len(name)
    for _ in range(3):
        at += 5 + struct.unpack("<I", data[at + 1:at + 5])[0]
    assert data[at:at + 1] == b"I"
    return struct.unpack("<i", data[at + 1:at + 5])[0]


def test_fbx_header_declares_y_up_and_one_metre_units(fbx_batch):
    data = open(fbx_batch[0]["fbx"], "rb").read()
    assert _fbx_int_property(data, b"UpAxis") == 1  # Y
    assert _fbx_int_property(data, b"FrontAxis") == 2 and _fbx_int_property(data, b"FrontAxisSign") == 1
    assert _fbx_double_property(data, b"UnitScaleFactor") == 100.0  # one file unit = 100 cm


def test_fbx_embeds_the_glb_textures(fbx_batch, tree_fbx_read_back):
    data = open(fbx_batch[0]["fbx"], "rb").read()
    assert b"bark_texture.png" in data and b"leaves_texture.png" in data
    assert b"\x89PNG\r\n\x1a\n" in data  # the pixels themselves, not a path to them
    assert {"bark_texture", "leaves_texture"} <= set(tree_fbx_read_back["textures"])


@pytest.mark.parametrize("index, lod", [(1, "LOD0"), (2, "LOD1")])
def test_fbx_of_a_lod_node_holds_only_that_lods_triangles(fbx_batch, index, lod):
    assert fbx_batch[index]["triangles"] == LOD_TRIANGLES[lod]
    assert all(name.startswith(lod) for name in fbx_batch[index]["triangles_per_object"])


def test_fbx_of_a_lod_node_reimports_with_its_triangles(fbx_batch):
    assert read_fbx(fbx_batch[2]["fbx"])["triangles"] == LOD_TRIANGLES["LOD1"]


def test_fbx_joins_instanced_leaves_into_one_mesh_object(fbx_batch):
    assert fbx_batch[3]["triangles_per_object"] == {"X_LOD0_bark": 12, "X_LOD0_leaves": 2 * N_LEAVES}


def test_fbx_of_instanced_leaves_reimports_with_every_leaf(fbx_batch):
    read = read_fbx(fbx_batch[3]["fbx"])
    assert {r["name"]: r["triangles"] for r in read["objects"]} == {"X_LOD0_bark": 12, "X_LOD0_leaves": 2 * N_LEAVES}


def test_fbx_exports_a_lod_node_outside_the_gltf_scene(fbx_batch):
    assert fbx_batch[4]["triangles_per_object"] == {"X_LOD1_bark": 1}


# Blender 5.0's glTF importer pairs custom attributes with their data in a str-hash order: with these seeds
# it meets _WIND and _WIND_PIVOT in one order and then the other (checked with CPython 3.11's hash).
@pytest.mark.parametrize("hash_seed", ["0", "4"])
def test_fbx_of_a_glb_with_wind_attributes_imports_whatever_the_hash_seed(instanced_glb, tmp_path, monkeypatch,
                                                                        hash_seed):
    monkeypatch.setenv("PYTHONHASHSEED", hash_seed)  # the worker process inherits it
    row = export_fbx(instanced_glb, tmp_path / "x.fbx", node="X_LOD0")
    assert row["triangles_per_object"]["X_LOD0_bark"] == 12


def test_fbx_bytes_depend_only_on_the_glb_not_on_the_run_or_folder(tree, fbx_batch, tmp_path):
    again = export_fbx(tree[1], tmp_path / "elsewhere" / "sapling.fbx", name="sapling_0001")
    assert open(again["fbx"], "rb").read() == open(fbx_batch[0]["fbx"], "rb").read()


# ------------------------------------------------------------------------------------------- FBX errors
def test_fbx_of_a_missing_glb_names_the_path(tmp_path):
    with pytest.raises(BlenderError, match="no-such.glb.*does not exist"):
        export_fbx(tmp_path / "no-such.glb", tmp_path / "out.fbx")


def test_fbx_of_a_file_that_is_not_a_glb_fails_with_the_log_tail(tmp_path):
    fake = tmp_path / "fake.glb"
    fake.write_bytes(b"\x89PNG\r\n\x1a\n not a model")
    with pytest.raises(BlenderError, match=r"(?s)invalid.*last lines of its log.*is not a GLB file"):
        export_fbx(fake, tmp_path / "out.fbx")
    assert not (tmp_path / "out.fbx").exists()


def test_fbx_of_a_corrupt_glb_fails_with_the_log_tail(tree, tmp_path):
    broken = tmp_path / "broken.glb"
    broken.write_bytes(tree[1].read_bytes()[:200])  # a GLB header, then the file stops
    with pytest.raises(BlenderError, match="(?s)invalid.*last lines of its log.*importer could not read.*broken.glb"):
        export_fbx(broken, tmp_path / "out.fbx")
    assert not (tmp_path / "out.fbx").exists()


@pytest.mark.parametrize("job, message", [
    ([], "at least one"),
    ([("a.glb",)], "must be"),
])
def test_fbx_batch_rejects_malformed_jobs(job, message):
    with pytest.raises(BlenderError, match=message):
        export_fbx_batch(job)


def test_fbx_output_must_end_in_fbx(tree, tmp_path):
    with pytest.raises(BlenderError, match="must end in .fbx"):
        export_fbx(tree[1], tmp_path / "out.obj")


# ------------------------------------------------------------------------------------------- .blend
def test_blend_lists_every_asset_as_a_collection(library):
    _, assets, _ = library
    assert sorted(assets) == ["X", "boxes_lod0", "sapling_0001", "sapling_0002"]
    assert {row["type"] for row in assets.values()} == {"collections"}


def test_blend_assets_keep_their_tags_description_and_properties(library):
    _, assets, _ = library
    first = assets["sapling_0001"]
    assert first["tags"] == ["sapling", "broadleaf"] and first["description"] == "a young sapling"
    assert first["properties"] == {"seed": 5}


def test_blend_assets_point_at_their_catalog_in_the_cats_file(library):
    written, assets, _ = library
    assert assets["sapling_0001"]["catalog_id"] == catalog_uuid("Trees/Sapling")
    assert assets["boxes_lod0"]["catalog_path"] == "Tests/Boxes"
    listed = read_catalog_file(written["blend"].rsplit("/", 1)[0])
    assert {"Trees", "Trees/Sapling", "Tests", "Tests/Boxes"} == set(listed)
    assert written["catalogs"] == listed


def test_the_adapter_stores_the_catalog_id_it_is_given(library):
    written, _, _ = library
    read = inspect_blend(written["blend"])  # the adapter alone: ids, no catalog paths
    ids = {row["name"]: row["catalog_id"] for row in read["assets"]}
    assert ids == {row["id"]: row["catalog_id"] for row in written["assets"]}
    assert "catalog_path" not in read["assets"][0]


def test_given_preview_is_stored_at_256_pixels_with_its_colours(library):
    _, assets, _ = library
    first = assets["sapling_0001"]
    assert first["has_preview"] and first["preview_size"] == [256, 256]
    np.testing.assert_allclose(first["preview_mean_rgba"], [*(np.array(PREVIEW_RGB) / 255), 1.0], atol=0.01)


def test_missing_preview_is_drawn_from_the_mesh(library):
    written, assets, _ = library
    assert [row["preview_generated"] for row in written["assets"]] == [False, True, True, True]
    drawn = assets["sapling_0002"]
    assert drawn["has_preview"] and 0.0 < drawn["preview_mean_rgba"][3] < 1.0  # a tree on a clear background


def test_blend_asset_holds_the_glb_triangles(tree, library):
    mesh, _ = tree
    _, assets, _ = library
    assert assets["sapling_0002"]["triangles"] == len(mesh.bark.faces) + len(mesh.leaves.faces)


def test_blend_asset_of_a_lod_node_holds_only_that_lod(library):
    _, assets, _ = library
    assert assets["boxes_lod0"]["triangles"] == LOD_TRIANGLES["LOD0"]


def test_blend_keeps_nothing_but_the_assets(library):
    _, assets, read = library
    assert read["collections"] == len(assets)  # no importer collections ("Orphan Nodes") left behind
    assert read["objects"] == sum(row["object_count"] for row in assets.values())
    assert assets["X"]["triangles"] == 12 + 2 * N_LEAVES  # X_LOD1 dropped, instances joined


def test_blend_asset_instance_places_the_tree_where_the_glb_has_it(tree, library):
    mesh, _ = tree
    _, assets, _ = library
    vertices = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    expected = np.stack([vertices.min(axis=0), vertices.max(axis=0)])
    for name in ("sapling_0001", "sapling_0002"):  # laid out side by side in the file, same offset back
        np.testing.assert_allclose(np.array(assets[name]["bounds"]), expected, atol=1e-3)


def test_blend_is_saved_uncompressed(library):
    written, _, _ = library
    assert open(written["blend"], "rb").read(7) == b"BLENDER"  # a compressed file starts with zstd's magic


def test_blend_written_again_is_byte_identical(library_assets, library, tmp_path):
    """Blender leaves random node ids, a clock-seeded colour seed and stale bytes after strings in a saved file;
    the worker rewrites them (renderers/blender_worker/blend_bytes.py), so the same assets give the same file."""
    written, assets, _ = library
    again = write_blender_library(library_assets, tmp_path / "saplings.blend")
    assert open(again["blend"], "rb").read() == open(written["blend"], "rb").read()


# ------------------------------------------------------------------------------------------- catalogs and errors
def test_catalog_file_merges_libraries_and_keeps_uuids(tmp_path):
    first = write_catalog_file(tmp_path, ["Trees/Fir"])
    second = write_catalog_file(tmp_path, ["Trees/Maple"])
    assert set(second) == {"Trees", "Trees/Fir", "Trees/Maple"}
    assert second["Trees/Fir"] == first["Trees/Fir"] == catalog_uuid("Trees/Fir")
    assert read_catalog_file(tmp_path) == second
    assert "VERSION 1" in (tmp_path / CATALOG_FILE).read_text().splitlines()


@pytest.mark.parametrize("path", ["", "Trees//Fir", "Trees/Fi:r", "   "])
def test_bad_catalog_paths_are_rejected(path, tmp_path):
    with pytest.raises(BlenderError, match="catalog path"):
        write_catalog_file(tmp_path, [path])


def test_library_rejects_repeated_ids(tree, tmp_path):
    asset = {"id": "same", "glb_path": tree[1], "tags": []}
    with pytest.raises(BlenderError, match="unique.*same"):
        write_blender_library([asset, asset], tmp_path / "lib.blend")


@pytest.mark.parametrize("change, message", [
    ({"glb_path": "/no/such.glb"}, "does not exist"),
    ({"preview_png": "/no/such.png"}, "preview_png"),
    ({"tags": "sapling"}, "list of non-empty strings"),
    ({"id": ""}, "non-empty string"),
])
def test_library_rejects_bad_assets_before_starting_blender(tree, tmp_path, change, message):
    asset = {"id": "a", "glb_path": tree[1], "tags": ["t"], **change}
    with pytest.raises(BlenderError, match=message):
        write_blender_library([asset], tmp_path / "lib.blend")
    assert not list(tmp_path.iterdir())  # nothing written


@pytest.mark.parametrize("catalog_id", [None, "Trees/Sapling", "6f1d6a52-3c1e"])
def test_adapter_rejects_an_asset_without_a_catalog_uuid(tree, tmp_path, catalog_id):
    asset = {"id": "a", "glb_path": tree[1], "tags": [], "catalog_id": catalog_id}
    with pytest.raises(BlenderError, match="catalog_id.*must be a UUID"):
        write_asset_library([asset], tmp_path / "lib.blend")
    assert not list(tmp_path.iterdir())


def test_library_of_a_file_that_is_not_a_glb_fails_with_the_log_tail(tmp_path):
    fake = tmp_path / "fake.glb"
    fake.write_text("hello")
    with pytest.raises(BlenderError, match=r"(?s)last lines of its log.*is not a GLB file"):
        write_blender_library([{"id": "a", "glb_path": fake, "tags": []}], tmp_path / "lib" / "lib.blend")
    assert not (tmp_path / "lib").exists()  # neither the .blend nor the catalog file


def test_inspect_of_a_missing_blend_names_the_path(tmp_path):
    with pytest.raises(BlenderError, match="nothing.blend.*does not exist"):
        inspect_blend(tmp_path / "nothing.blend")


def test_deterministic_rewrite_changes_nothing_the_second_time(library, tmp_path):
    written, _, _ = library
    copy = tmp_path / "copy.blend"
    copy.write_bytes(open(written["blend"], "rb").read())
    assert make_deterministic(copy) == 0  # the worker already rewrote it
    assert copy.read_bytes() == open(written["blend"], "rb").read()


@pytest.mark.parametrize("content, message", [
    (b"BLENDER-v300REND", "not an uncompressed Blender 5 file"),
    (b"\x28\xb5\x2f\xfd compressed", "not an uncompressed Blender 5 file"),
    (b"BLENDER17-01v0500REND\0\0\0\0", "truncated"),
])
def test_deterministic_rewrite_refuses_other_files_and_leaves_them(tmp_path, content, message):
    path = tmp_path / "other.blend"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message):
        make_deterministic(path)
    assert path.read_bytes() == content
