"""A library asset with an octahedral impostor, read by real clients: the GLB passes the Khronos validator and holds
the layout on its IMPOSTOR node, the USD passes UsdValidation with the layout as custom data, Blender imports the
impostor's FBX back; asset.json records the layout and a measured IoU; a rerun gives the same bytes.

One palm built twice by `farm library add` (no Ray, 32 px textures, 8 x 8 frames of 48 px)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from farm.library.job import add_asset
from farm.library.records import write_library_record
from farm.library.spec import parse_library_spec
from farm.dataset.storage import Location
from gltf_validator import assert_valid_glb
from usd_validator import assert_valid_usd
from renderers.blender import blender_available
from species.meshing.gltf import read_glb_chunks

SPEC = {"name": "octahedral", "seed": 1, "species": {"palm": 1}, "formats": ["glb", "usd", "obj", "fbx"],
        "texture_size": 32, "impostor": "octahedral", "impostor_frames": 8, "impostor_tile": 48}


def _built(folder: Path) -> Path:
    write_library_record(Location.resolve(str(folder)), parse_library_spec(SPEC))
    add_asset(str(folder), "palm", 3)
    return next(folder.glob("assets/*/asset.json")).parent


@pytest.fixture(scope="module")
def asset(tmp_path_factory) -> Path:
    """The palm's asset folder (treat as read-only)."""
    return _built(tmp_path_factory.mktemp("octahedral") / "library")


@pytest.fixture(scope="module")
def record(asset) -> dict:
    return json.loads((asset / "asset.json").read_text())


def test_asset_json_records_the_layout_and_the_impostor_as_one_quad(record):
    layout = record["impostor"]
    assert (layout["kind"], layout["mapping"], layout["frames"], layout["tile_px"], layout["atlas_px"]) == (
        "octahedral", "hemi-octahedral", 8, 48, 384)
    impostor = record["levels"][-1]
    assert impostor["name"] == "IMPOSTOR" and impostor["triangles"] == 2 and impostor["switch_px"] == 64


def test_the_impostor_iou_is_measured_from_the_quality_azimuths_in_a_sane_range(record):
    impostor = record["levels"][-1]
    assert len(impostor["iou_per_azimuth"]) == 8
    assert 0.5 < impostor["iou_min"] <= impostor["iou_mean"] < 1.0


def test_the_glb_passes_the_validator_and_carries_the_layout_on_its_impostor_node(asset, record, tmp_path):
    glb = next(asset.glob("*.glb"))
    report = assert_valid_glb(glb.read_bytes(), tmp_path, glb.name)
    assert report["issues"]["numWarnings"] == 0
    document, _ = read_glb_chunks(glb.read_bytes())
    node = next(n for n in document["nodes"] if n["name"].endswith("_IMPOSTOR"))
    assert node["extras"]["impostor"] == record["impostor"]
    quad = document["meshes"][document["nodes"][node["children"][0]]["mesh"]]["primitives"][0]
    assert document["accessors"][quad["indices"]]["count"] == 6 and "TANGENT" in quad["attributes"]
    images = {image["name"] for image in document["images"]}
    assert {"impostor_albedo", "impostor_normal"} <= images


def test_the_usd_validates_and_holds_the_layout_on_the_impostor_prim(asset, record):
    from pxr import Usd

    stage = Usd.Stage.Open(str(next(asset.glob("*.usdc"))))
    assert_valid_usd(stage)
    root = stage.GetDefaultPrim()
    root.GetVariantSets().GetVariantSet("lod").SetVariantSelection("IMPOSTOR")
    custom = stage.GetPrimAtPath(root.GetPath().AppendPath("Geom/impostor")).GetCustomDataByKey("treefarm:impostor")
    assert custom["frames"] == 8 and custom["mapping"] == "hemi-octahedral"
    assert list(custom["centre_m"]) == record["impostor"]["centre_m"]
    assert custom["radius_m"] == record["impostor"]["radius_m"]


def test_blender_imports_the_impostor_fbx_back_as_one_quad(asset, record):
    if not blender_available():
        pytest.skip("Blender is not installed (.venv-blender): run `make env`")
    from renderers.blender_assets import read_fbx

    assert record["blender"] == "written"
    read = read_fbx(asset.parent.parent / record["files"]["fbx_IMPOSTOR"])
    assert read["triangles"] == 2
    assert any(name.startswith("impostor_albedo") for name in read["textures"])


def test_a_second_build_gives_the_same_bytes(asset, tmp_path):
    again = _built(tmp_path / "library")
    files = sorted(p.relative_to(asset) for p in asset.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    assert [f for f in files if (asset / f).read_bytes() != (again / f).read_bytes()] == []
