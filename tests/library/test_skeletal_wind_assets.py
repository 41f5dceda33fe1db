"""An asset with baked skeletal wind, read by real clients: the GLB passes the Khronos validator with every level
skinned to the same joints, leaves instanced under them and a `wind` animation of the clip's length; the USD
passes UsdValidation with a UsdSkel Skeleton and SkelAnimation; Blender imports the GLB and the FBX with armatures
and an action of the clip's length, and the LOD-group FBX with every skinned level's armature under its LodGroup
node. Bad wind settings are refused in one line with exit status 2.

One palm built by `farm library add` (no Ray, 32 px textures, a 4 s clip, at most 16 joints)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from farm.cli import main as farm_main
from farm.library.spec import default_library_spec
from gltf_validator import assert_valid_glb
from one_asset_library import one_asset_library
from usd_validator import assert_valid_usd
from renderers.blender import blender_available, glb_info
from species.meshing.gltf import read_accessor, read_glb_chunks

PERIOD_S, JOINTS = 4.0, 16
SPEC = {"name": "skeletal", "seed": 1, "species": {"palm": 1}, "formats": ["glb", "usd", "fbx"], "texture_size": 32,
        "impostor_tile": 16, "skeletal_wind": True, "wind_joints": JOINTS, "wind_period_s": PERIOD_S}


@pytest.fixture(scope="module")
def asset(tmp_path_factory) -> Path:
    """The palm's asset folder (treat as read-only)."""
    return one_asset_library(tmp_path_factory.mktemp("skeletal") / "library", SPEC, "palm", 3)


@pytest.fixture(scope="module")
def record(asset) -> dict:
    return json.loads((asset / "asset.json").read_text())


@pytest.fixture(scope="module")
def document(asset) -> tuple[dict, bytes]:
    return read_glb_chunks(next(asset.glob("*.glb")).read_bytes())


def test_asset_json_records_the_joints_within_the_budget_and_the_clip(record):
    wind = record["skeletal_wind"]
    assert 4 < wind["joints"] <= JOINTS and wind["joints"] == len(wind["joint_names"])
    assert wind["joint_names"][0] == "trunk_0" and wind["joint_parents"][0] == -1
    assert wind["period_s"] == PERIOD_S and wind["animation"] == "wind"


def test_the_glb_is_valid_with_every_level_skinned_to_the_same_joints(asset, document, record, tmp_path):
    glb = next(asset.glob("*.glb"))
    report = assert_valid_glb(glb.read_bytes(), tmp_path, glb.name)
    assert report["issues"]["numWarnings"] == 0
    doc, _ = document
    names = record["skeletal_wind"]["joint_names"]
    levels = [lv["name"] for lv in record["levels"] if lv["name"] != "IMPOSTOR"]
    assert len(doc["skins"]) == len(levels)
    for skin, level in zip(doc["skins"], levels):
        assert [doc["nodes"][j]["name"] for j in skin["joints"]] == [f"wind_{n}" for n in names]
        node = next(n for n in doc["nodes"] if n["name"] == f"{record['id']}_{level}")
        assert doc["skins"][node["skin"]] is skin
        primitives = doc["meshes"][node["mesh"]]["primitives"]
        assert all({"JOINTS_0", "WEIGHTS_0"} <= set(p["attributes"]) for p in primitives)


def test_lod0_leaves_are_instanced_under_the_joints_they_follow(document, record):
    doc, _ = document
    lod0_skin = doc["skins"][0]
    under_joints = [child for j in lod0_skin["joints"] for child in doc["nodes"][j].get("children", [])
                    if "EXT_mesh_gpu_instancing" in doc["nodes"][child].get("extensions", {})]
    count = sum(doc["accessors"][doc["nodes"][n]["extensions"]["EXT_mesh_gpu_instancing"]["attributes"]
                                 ["TRANSLATION"]]["count"] for n in under_joints)
    lod0 = next(n for n in doc["nodes"] if n["name"] == f"{record['id']}_LOD0")
    bark_triangles = doc["accessors"][doc["meshes"][lod0["mesh"]]["primitives"][0]["indices"]]["count"] // 3
    assert len(under_joints) >= 2
    assert 2 * count == record["levels"][0]["triangles"] - bark_triangles  # every LOD0 leaf card, two triangles


def test_the_wind_animation_turns_every_levels_joints_and_leans_the_impostor_over_one_period(document, record):
    doc, binary = document
    (animation,) = doc["animations"]
    joints = record["skeletal_wind"]["joints"]
    assert animation["name"] == "wind" and len(animation["channels"]) == len(doc["skins"]) * joints + 1
    times = read_accessor(doc, binary, animation["samplers"][0]["input"])
    assert times[0] == 0.0 and times[-1] == pytest.approx(PERIOD_S)
    lean = animation["channels"][-1]["target"]["node"]
    assert doc["nodes"][lean]["name"] == f"{record['id']}_IMPOSTOR_lean"
    rotations = read_accessor(doc, binary, animation["samplers"][1]["output"])
    assert (rotations[0] == rotations[-1]).all() and abs(rotations - rotations[0]).max() > 1e-4


def test_the_usd_validates_with_a_skeleton_and_its_animation(asset, record):
    from pxr import UsdSkel

    stage = assert_valid_usd(next(asset.glob("*.usdc")))
    root = stage.GetDefaultPrim()
    geom = root.GetPath().AppendPath("Geom")
    skeleton = UsdSkel.Skeleton(stage.GetPrimAtPath(geom.AppendPath("Skel")))
    animation = UsdSkel.Animation(stage.GetPrimAtPath(geom.AppendPath("Skel/wind")))
    assert len(skeleton.GetJointsAttr().Get()) == record["skeletal_wind"]["joints"]
    samples = animation.GetRotationsAttr().GetTimeSamples()
    assert len(samples) == record["skeletal_wind"]["keys"]
    assert (stage.GetEndTimeCode() - stage.GetStartTimeCode()) / stage.GetTimeCodesPerSecond() == PERIOD_S
    for level in ("LOD0", "LOD3"):
        root.GetVariantSets().GetVariantSet("lod").SetVariantSelection(level)
        bark = UsdSkel.BindingAPI(stage.GetPrimAtPath(geom.AppendPath("bark")))
        assert bark.GetSkeletonRel().GetTargets() == [skeleton.GetPath()]


def test_blender_imports_the_glb_with_an_armature_per_level_and_the_clip(asset, record):
    # The GLB Blender makes the FBX files from: the asset's own skeleton and clip, leaves baked into the skinned
    # mesh (Blender imports thousands of leaf instances far slower).
    if not blender_available():
        pytest.skip("Blender is not installed (.venv-blender): run `make env`")
    seen = glb_info(asset.parent.parent / record["files"]["glb_flat"])
    assert len(seen["armatures"]) == 4
    assert all(a["bones"] == record["skeletal_wind"]["joints"] for a in seen["armatures"])
    (action,) = [a for a in seen["actions"] if a["name"] == "wind"]
    assert action["seconds"] == pytest.approx(PERIOD_S)


def test_blender_imports_the_fbx_with_an_armature_and_an_action_of_the_clips_length(asset, record):
    if not blender_available():
        pytest.skip("Blender is not installed (.venv-blender): run `make env`")
    from renderers.blender_assets import read_fbx

    assert record["blender"] == "written"
    lod0 = read_fbx(asset.parent.parent / record["files"]["fbx_LOD0"])
    assert [a["bones"] for a in lod0["armatures"]] == [record["skeletal_wind"]["joints"]]
    assert lod0["actions"] and all(a["seconds"] == pytest.approx(PERIOD_S) for a in lod0["actions"])
    impostor = read_fbx(asset.parent.parent / record["files"]["fbx_IMPOSTOR"])
    assert any(a["seconds"] == pytest.approx(PERIOD_S) for a in impostor["actions"])


def test_the_lod_group_fbx_holds_every_skinned_level_as_its_armature_under_its_lod_group_node(asset, record):
    """Every level with branches is its armature (bones named as the joints) holding its skinned mesh, named as
    the file without wind names it; one action of the clip's length per armature, and the impostor's lean."""
    if not blender_available():
        pytest.skip("Blender is not installed (.venv-blender): run `make env`")
    from renderers.blender_assets import read_fbx

    read = read_fbx(asset.parent.parent / record["files"]["fbx"])
    (group,) = read["lod_groups"]
    names = record["lod_group"]["names"]
    assert group["name"] == record["id"] and group["children"] == names
    joints = record["skeletal_wind"]["joints"]
    assert read["armatures"] == [{"name": name, "bones": joints} for name in names[:-1]]
    assert {a["name"].split("|")[0] for a in read["actions"]} >= {*names[:-1], f"{names[-1]}_lean"}
    assert all(a["seconds"] == pytest.approx(PERIOD_S) for a in read["actions"])
    assert sorted(o["name"] for o in read["objects"]) == [f"{name}_bark" for name in names[:-1]] + [f"{names[-1]}_card"]
    triangles = {name: sum(o["triangles"] for o in read["objects"] if o["name"].startswith(f"{name}_"))
                 for name in group["children"]}
    assert list(triangles.values()) == [level["triangles"] for level in record["levels"]]


@pytest.mark.parametrize("fields, named", [({"skeletal_wind": True, "wind_joints": 3}, "wind_joints"),
                                           ({"skeletal_wind": True, "wind_period_s": 0}, "wind_period_s"),
                                           ({"skeletal_wind": True, "wind_period_s": -2.0}, "wind_period_s"),
                                           ({"wind_gust": 0.3}, "wind_gust")])
def test_bad_wind_settings_are_refused_in_one_line_with_nothing_written(tmp_path, capsys, fields, named):
    spec = tmp_path / "spec.yaml"
    spec.write_text(json.dumps({"species": {"palm": 1}, **fields}))
    out = tmp_path / "out"
    assert farm_main(["library", str(spec), "--out", str(out), "--quiet"]) == 2
    error = capsys.readouterr().err.strip().splitlines()
    assert len(error) == 1 and named in error[0] and not out.exists()


def test_the_default_spec_carries_no_wind_clip_and_keeps_its_record():
    spec = default_library_spec()
    assert spec.wind_clip is None and not any(key.startswith(("wind_", "skeletal")) for key in spec.to_dict())
