"""The engine LOD-group FBX (`farm.library.lod_group`): one file per asset holding every level as `<id>_LOD0` ...
with the impostor last, read back by Blender's importer with each level's triangle count from asset.json and each
image embedded once; the per-level files stay. `leaves: cutout` assets carry their outline polygons into FBX
with an opaque leaf material. And `fbx` asked for without Blender: one line, exit 2, nothing written.

Blender runs for real (`.venv-blender`, built by `make env`): one export batch for the module, then one import
per file read back.
"""
from __future__ import annotations

import hashlib
import re

import pytest
import yaml

import farm.library.job as library_job
from farm.cli import main as farm_main
from farm.library.lod_group import unity_transitions, unreal_screen_sizes

PNG_START, PNG_END = b"\x89PNG\r\n\x1a\n", b"IEND\xaeB`\x82"
ASSETS = {"cards": ("maple", 5), "cutout": ("sc_young_sapling", 0)}


def _embedded_pngs(fbx: bytes) -> list[str]:
    """sha256 of every PNG stored whole in the FBX's bytes, in file order."""
    return [hashlib.sha256(m.group(0)).hexdigest()
            for m in re.finditer(re.escape(PNG_START) + b".*?" + re.escape(PNG_END), fbx, re.DOTALL)]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """{leaves: (asset.json record, library folder)}: a maple with leaf cards and a sapling with cutout leaves,
    their FBX files exported in one Blender process (`finish_assets`)."""
    from farm.dataset.storage import Location
    from farm.library.asset import build_asset
    from farm.library.spec import parse_library_spec
    from farm.tree_chain import tree_seed
    from renderers.gl_coverage import CoverageRenderer
    from species.timing import StageTimer

    folder = tmp_path_factory.mktemp("lod_group")
    location = Location.resolve(str(folder))
    renderer = CoverageRenderer(64)
    pending, specs = [], {}
    try:
        for leaves, (name, seed) in ASSETS.items():
            specs[leaves] = parse_library_spec({"species": {name: 1}, "leaves": leaves, "texture_size": 64,
                                                "impostor_tile": 32, "formats": ["glb", "fbx"]})
            asset = build_asset(name, tree_seed(seed, 0), specs[leaves], renderer, StageTimer())
            pending.append(library_job.stage_asset_files(asset, location, specs[leaves], renderer, StageTimer()))
    finally:
        renderer.close()
    records = library_job.finish_assets(pending, location, specs["cards"], StageTimer())
    return {leaves: (record, folder) for leaves, record in zip(ASSETS, records)}


@pytest.fixture(scope="module")
def read_back(exported):
    """{leaves: Blender's `read_fbx` of the asset's LOD-group file}."""
    from renderers.blender_assets import read_fbx

    return {leaves: read_fbx(folder / record["files"]["fbx"]) for leaves, (record, folder) in exported.items()}


@pytest.mark.parametrize("leaves", list(ASSETS))
def test_the_lod_group_file_holds_every_level_with_its_triangles_from_asset_json(exported, read_back, leaves):
    record, folder = exported[leaves]
    ident, levels = record["id"], record["levels"]
    assert record["blender"] == "written"
    assert record["lod_group"]["names"] == [f"{ident}_LOD{i}" for i in range(len(levels))]
    assert record["lod_group"]["levels"][-1] == "IMPOSTOR" and len(levels) == 5
    triangles = {}
    for row in read_back[leaves]["objects"]:
        level = re.fullmatch(rf"{re.escape(ident)}_LOD(\d)_\w+", row["name"])
        assert level, row["name"]
        triangles[int(level.group(1))] = triangles.get(int(level.group(1)), 0) + row["triangles"]
    assert triangles == {i: level["triangles"] for i, level in enumerate(levels)}
    # The per-level files stay.
    for level in levels:
        assert (folder / record["files"][f"fbx_{level['name']}"]).is_file()


@pytest.mark.parametrize("leaves", list(ASSETS))
def test_the_lod_group_file_embeds_each_image_once_and_every_image_of_its_levels(exported, leaves):
    record, folder = exported[leaves]
    embedded = _embedded_pngs((folder / record["files"]["fbx"]).read_bytes())
    assert embedded and len(embedded) == len(set(embedded))
    per_level = set()
    for level in record["levels"]:
        per_level |= set(_embedded_pngs((folder / record["files"][f"fbx_{level['name']}"]).read_bytes()))
    assert set(embedded) == per_level
    assert record["sizes"]["fbx"] < sum(record["sizes"][f"fbx_{lv['name']}"] for lv in record["levels"])


def test_cutout_leaves_reach_fbx_as_opaque_polygons(exported, read_back):
    record, _ = exported["cutout"]
    read = read_back["cutout"]
    leaf_materials = {m for row in read["objects"] if row["name"].endswith("_leaves") for m in row["materials"]}
    assert leaf_materials == {"leaf_cutout_summer"}
    assert "Alpha" not in read["bindings"]["leaf_cutout_summer"] and "Base Color" in \
        read["bindings"]["leaf_cutout_summer"]
    cards, _ = exported["cards"]
    assert "Alpha" in read_back["cards"]["bindings"]["leaves_summer"]  # cards keep their alpha test


def test_screen_sizes_follow_the_switch_sizes():
    switch = [0, 512, 256, 128, 64]
    unity = unity_transitions(switch, 10.0, 2.0)  # a tree taller than wide: the switch heights over 1080
    assert unity == [round(px / 1080, 4) for px in switch[1:]] + [0.0]
    assert unity_transitions(switch, 4.0, 4.0)[0] == round(512 / 1080 * 2.0, 4)  # the crown is the widest side
    unreal = unreal_screen_sizes(switch, 10.0, 2.0)
    assert unreal[0] == 1.0 and all(a > b for a, b in zip(unreal, unreal[1:]))
    assert all(u > v for u, v in zip(unreal[1:], unity))  # the sphere spans more than the height


def test_fbx_without_blender_is_one_line_exit_2_and_nothing_written(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(library_job, "blender_available", lambda: False)
    path = tmp_path / "spec.yaml"
    path.write_text(yaml.safe_dump({"species": {"palm": 1}, "formats": ["glb", "fbx"]}))
    assert farm_main(["library", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "formats" in err[0] and "fbx" in err[0] and "Blender" in err[0]
    assert not (tmp_path / "out").exists()
