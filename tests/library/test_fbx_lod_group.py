"""The engine LOD-group FBX (`farm.library.lod_group`): one file per asset holding every level as `<id>_LOD0` ...
with the impostor last, read back by Blender's importer with each level's triangle count from asset.json and each
image embedded once; the per-level files stay. The levels are the ordered children of an FBX LodGroup node whose
thresholds are asset.json's Unity transitions in percent, as Blender's own FBX parser and, where the `ufbx`
package is installed, ufbx read it. `leaves: cutout` assets carry their outline polygons into FBX with an opaque
leaf material. And `fbx` asked for without Blender: one line, exit 2, nothing written.

Blender runs for real (`.venv-blender`, built by `make env`): one export batch for the module, then one import
per file read back.
"""
from __future__ import annotations

import hashlib
import json
import re
import subprocess
import sys

import pytest
import yaml

import farm.library.job as library_job
from farm.cli import main as farm_main
from farm.library.fbx_binary import FbxFile, read_fbx_bytes, write_fbx_bytes
from farm.library.fbx_lod_node import add_lod_group_node
from farm.library.lod_group import lod_group_thresholds, unity_transitions, unreal_screen_sizes

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


@pytest.mark.parametrize("leaves", list(ASSETS))
def test_the_levels_are_the_ordered_children_of_an_fbx_lod_group_node(exported, read_back, leaves):
    record, _ = exported[leaves]
    entry = record["lod_group"]
    (group,) = read_back[leaves]["lod_groups"]  # as Blender's own FBX parser reads the records
    assert group["name"] == record["id"] and group["attribute"]
    assert group["children"] == entry["names"]
    props = group["properties"]
    assert props["ThresholdsUsedAsPercentage"] == 1 and props["MinMaxDistance"] == 0
    thresholds = [props[f"Thresholds|Level{i}"] for i in range(len(entry["names"]) - 1)]
    assert f"Thresholds|Level{len(entry['names']) - 1}" not in props
    assert thresholds == pytest.approx([100 * t for t in entry["unity_transition"][:-1]])
    assert all(a > b > 0 for a, b in zip(thresholds, thresholds[1:]))
    assert [props[f"DisplayLevels|Level{i}"] for i in range(len(entry["names"]))] == [0] * len(entry["names"])


# Each list the binding hands out is kept in a name while its items are read: reading through a temporary list
# crashed the binding (ufbx 0.0.5) now and then.
UFBX_READ = """
import json, sys, ufbx
scene = ufbx.load_file(sys.argv[1])
groups, out = scene.lod_groups, []
for g in range(len(groups)):
    group = groups[g]
    instances, levels = group.instances, group.lod_levels
    node = instances[0]
    children = node.children
    out.append({"node": node.name, "type": node.attrib_type.name, "relative": group.relative_distances,
                "children": [children[i].name for i in range(len(children))],
                "distances": [levels[i].distance for i in range(len(levels))]})
print(json.dumps(out))
"""


def test_ufbx_reads_the_lod_group_as_asset_json_says(exported):
    """An independent reader (ufbx, a C library): the group node, its levels in order, the thresholds. It runs
    in a child process, so a crash of the binding fails this test rather than the session."""
    pytest.importorskip("ufbx")
    for record, folder in exported.values():
        run = subprocess.run([sys.executable, "-c", UFBX_READ, str(folder / record["files"]["fbx"])],
                             capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stderr
        (group,) = json.loads(run.stdout)
        entry = record["lod_group"]
        assert group["node"] == record["id"] and group["type"] == "LOD_GROUP" and group["relative"]
        assert group["children"] == entry["names"]
        # ufbx lists one level more than the thresholds: the first, shown from the full screen down.
        assert group["distances"][1:] == pytest.approx(lod_group_thresholds(entry))


def _object_counts(data: bytes) -> dict:
    """{object type: count} as the file's Definitions say."""
    definitions = next(r for r in read_fbx_bytes(data).records if r.name == b"Definitions")
    return {r.values()[0]: r.first(b"Count").values()[0] for r in definitions.children if r.name == b"ObjectType"}


def test_fbx_records_round_trip_and_the_group_is_added_only_once_levels_are_found(exported):
    record, folder = exported["cards"]
    for path in [record["files"]["fbx"], *(record["files"][f"fbx_{lv['name']}"] for lv in record["levels"])]:
        data = (folder / path).read_bytes()
        fbx = read_fbx_bytes(data)
        assert write_fbx_bytes(fbx) == data
    # Version 7500 stores offsets and counts in 64 bits: the same records through that layout and back.
    wide = read_fbx_bytes(write_fbx_bytes(FbxFile(7500, fbx.records, fbx.footer)))
    assert wide.version == 7500 and write_fbx_bytes(FbxFile(fbx.version, wide.records, wide.footer)) == data
    level = (folder / record["files"]["fbx_LOD0"]).read_bytes()  # one level at the top: LOD0's own node
    ident = record["id"]
    with pytest.raises(ValueError, match="LOD1"):
        add_lod_group_node(level, ident, [f"{ident}_LOD0", f"{ident}_LOD1"], [50.0])
    with pytest.raises(ValueError, match="2 levels need 1 thresholds"):
        add_lod_group_node(level, ident, [f"{ident}_LOD0", f"{ident}_LOD1"], [])
    with pytest.raises(ValueError, match="not a binary FBX"):
        add_lod_group_node(b"; FBX 7.4.0 project file", ident, [f"{ident}_LOD0"], [])
    one = add_lod_group_node(level, ident, [f"{ident}_LOD0"], [])
    assert one == add_lod_group_node(level, ident, [f"{ident}_LOD0"], [])  # same bytes: ids from names
    before = _object_counts(level)
    assert _object_counts(one) == {**before, b"Model": before[b"Model"] + 1,
                                   b"NodeAttribute": before[b"NodeAttribute"] + 1}


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
