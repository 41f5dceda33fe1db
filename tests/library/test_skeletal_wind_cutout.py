"""Baked skeletal wind with `leaves: cutout`: the leaves that move with their joints are the opaque outline
polygons, not cards, in every file. The GLB passes the Khronos validator with LOD0's polygons instanced under the
joints the clip turns (and the baked GLB skins them); the USD passes UsdValidation with every joint's leaf
prototype the polygon bound to the opaque material in each season; Blender imports the LOD0 FBX with its
armature and the polygons at asset.json's triangle count.

One young sapling built by `farm library add` (no Ray, 32 px textures, a 4 s clip, at most 16 joints); its LOD3
holds clump cards too."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gltf_validator import assert_valid_glb
from one_asset_library import one_asset_library
from renderers.blender import blender_available
from species.meshing.gltf import read_accessor, read_glb_chunks
from species.studio.pbr_textures import SEASONS
from usd_validator import assert_valid_usd

PERIOD_S, JOINTS = 4.0, 16
SPEC = {"name": "skeletal_cutout", "seed": 1, "species": {"sc_young_sapling": 1}, "formats": ["glb", "usd", "fbx"],
        "texture_size": 32, "impostor_tile": 16, "leaves": "cutout", "skeletal_wind": True, "wind_joints": JOINTS,
        "wind_period_s": PERIOD_S}


@pytest.fixture(scope="module")
def asset(tmp_path_factory) -> Path:
    """The sapling's asset folder (treat as read-only)."""
    return one_asset_library(tmp_path_factory.mktemp("skeletal_cutout") / "library", SPEC, "sc_young_sapling", 0)


@pytest.fixture(scope="module")
def record(asset) -> dict:
    return json.loads((asset / "asset.json").read_text())


def _triangles(doc: dict, primitive: dict) -> int:
    return doc["accessors"][primitive["indices"]]["count"] // 3


def _material(doc: dict, primitive: dict) -> str:
    return doc["materials"][primitive["material"]]["name"]


def test_the_glb_is_valid_with_lod0s_outline_polygons_under_the_joints_the_clip_turns(asset, record, tmp_path):
    glb = asset / f"{record['id']}.glb"
    report = assert_valid_glb(glb.read_bytes(), tmp_path, glb.name)
    assert report["issues"]["numWarnings"] == 0
    doc, binary = read_glb_chunks(glb.read_bytes())
    lod0 = next(n for n in doc["nodes"] if n["name"] == f"{record['id']}_LOD0")
    joints = doc["skins"][lod0["skin"]]["joints"]
    (bark,) = doc["meshes"][lod0["mesh"]]["primitives"]
    holders, drawn = set(), 0
    for j in joints:
        for child in doc["nodes"][j].get("children", []):
            node = doc["nodes"][child]
            if "EXT_mesh_gpu_instancing" not in node.get("extensions", {}):
                continue
            (card,) = doc["meshes"][node["mesh"]]["primitives"]
            assert _material(doc, card) == "leaf_cutout_summer" and _triangles(doc, card) > 2  # a polygon, not a card
            instances = node["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]["TRANSLATION"]
            count = doc["accessors"][instances]["count"]
            holders.add(j)
            drawn += count * _triangles(doc, card)
    assert len(holders) >= 2 and _triangles(doc, bark) + drawn == record["levels"][0]["triangles"]
    # Each joint holding leaves is turned by the clip: its keys change over the loop and end where they start.
    (animation,) = doc["animations"]
    for channel in animation["channels"]:
        if channel["target"]["node"] in holders:
            keys = read_accessor(doc, binary, animation["samplers"][channel["sampler"]]["output"])
            assert np.abs(keys - keys[0]).max() > 1e-4 and np.array_equal(keys[0], keys[-1])
            holders.discard(channel["target"]["node"])
    assert not holders


def test_the_baked_glb_skins_the_polygons_and_keeps_the_clump_cards(asset, record, tmp_path):
    # Blender's input for the FBX files: the leaves baked into each level's skinned mesh.
    data = (asset.parent.parent / record["files"]["glb_flat"]).read_bytes()
    assert_valid_glb(data, tmp_path, "flat.glb")
    doc, _ = read_glb_chunks(data)
    for level in record["levels"][:-1]:
        node = next(n for n in doc["nodes"] if n["name"] == f"{record['id']}_{level['name']}")
        primitives = doc["meshes"][node["mesh"]]["primitives"]
        assert all({"JOINTS_0", "WEIGHTS_0"} <= set(p["attributes"]) for p in primitives)
        assert sum(_triangles(doc, p) for p in primitives) == level["triangles"]
    lod3 = next(n for n in doc["nodes"] if n["name"] == f"{record['id']}_LOD3")
    materials = [_material(doc, p) for p in doc["meshes"][lod3["mesh"]]["primitives"]]
    assert "leaf_cutout_summer" in materials and "leaves_summer" in materials  # polygons and clump cards


def test_the_usd_binds_every_joints_leaf_polygon_to_the_opaque_material_in_each_season(asset, record):
    from pxr import Usd, UsdGeom, UsdShade

    stage = assert_valid_usd(asset / f"{record['id']}.usdc")
    root = stage.GetDefaultPrim()
    leaves = root.GetPath().AppendPath("Geom/leaves")
    seen = set()
    for level in ("LOD0", "LOD3"):
        root.GetVariantSets().GetVariantSet("lod").SetVariantSelection(level)
        for season in (s for s in SEASONS if s != "bare"):
            root.GetVariantSets().GetVariantSet("season").SetVariantSelection(season)
            instancers = [UsdGeom.PointInstancer(p) for p in Usd.PrimRange(stage.GetPrimAtPath(leaves))
                          if p.IsA(UsdGeom.PointInstancer)]
            assert len(instancers) >= 2
            for instancer in instancers:
                for target in instancer.GetPrototypesRel().GetTargets():
                    prototype = stage.GetPrimAtPath(target)
                    bound, _ = UsdShade.MaterialBindingAPI(prototype).ComputeBoundMaterial()
                    polygon = target.name == "leaf"
                    assert bound.GetPrim().GetName() == (f"leaves_cutout_{season}" if polygon else f"leaves_{season}")
                    points = len(UsdGeom.Mesh(prototype).GetPointsAttr().Get())
                    assert points > 4 if polygon else points == 4
                    shader = UsdShade.Shader(stage.GetPrimAtPath(bound.GetPath().AppendChild("surface")))
                    assert (shader.GetInput("opacity") is None or not shader.GetInput("opacity")) == polygon
                    seen.add((level, target.name))
    assert {("LOD0", "leaf"), ("LOD3", "leaf"), ("LOD3", "clump")} <= seen


def test_blender_imports_the_lod0_fbx_with_its_armature_and_the_outline_polygons(asset, record):
    if not blender_available():
        pytest.skip("Blender is not installed (.venv-blender): run `make env`")
    from renderers.blender_assets import read_fbx

    assert record["blender"] == "written"
    read = read_fbx(asset.parent.parent / record["files"]["fbx_LOD0"])
    assert [a["bones"] for a in read["armatures"]] == [record["skeletal_wind"]["joints"]]
    assert read["actions"] and all(a["seconds"] == pytest.approx(PERIOD_S) for a in read["actions"])
    assert read["triangles"] == record["levels"][0]["triangles"]
    materials = {m for row in read["objects"] for m in row["materials"]}
    assert materials == {"bark", "leaf_cutout_summer"}
    assert "Alpha" not in read["bindings"]["leaf_cutout_summer"]
