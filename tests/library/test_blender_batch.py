"""The library job's Blender outputs: one Blender batch per shard, fed the non-instanced GLB (the worker is
replaced by a recorder here; tests/library/test_blender_outputs.py drives the real one)."""
from __future__ import annotations

import json

import pytest

from farm.library import job
from farm.library.catalog import validate_library, write_catalog
from farm.library.records import write_library_record
from farm.library.spec import parse_library_spec
from farm.pipeline import plan_shards, run_shard
from farm.dataset.storage import Location
from renderers.blender import BlenderError
from species.meshing.gltf import read_glb_chunks

SPEC = {"species": {"sc_young_sapling": 3}, "formats": ["glb", "fbx"], "texture_size": 64, "impostor_tile": 32,
        "shard_size": 2}


@pytest.fixture(scope="module")
def shard_run(tmp_path_factory):
    batches = []

    def record_batch(jobs, timeout=0.0):
        batches.append(list(jobs))
        return [{"bytes": 100 + i} for i in range(len(jobs))]

    def record_group_node(location, relative, ident, entry):
        grouped.append((ident, entry["names"]))
        return 200

    grouped = []
    patch = pytest.MonkeyPatch()
    patch.setattr(job, "blender_available", lambda: True)
    patch.setattr(job, "export_fbx_batch", record_batch)
    # No file is written by the recorder: the LodGroup post-pass (tests/library/test_fbx_lod_group.py) is
    # recorded too.
    patch.setattr(job, "write_lod_group_node", record_group_node)
    try:
        spec = parse_library_spec(SPEC)
        out = tmp_path_factory.mktemp("library")
        chain = job.LibraryChain(spec, str(out))
        records = [run_shard(spec, plan, Location.resolve(str(out)), chain) for plan in plan_shards(spec)]
    finally:
        patch.undo()
    assert len(grouped) == 3 and all(len(names) == 5 for _, names in grouped)  # 4 LODs and the impostor
    return out, batches, records


def test_each_shard_exports_its_assets_fbx_in_one_blender_batch(shard_run):
    out, batches, records = shard_run
    # assets x (4 LODs + impostor, a file each, and the LOD-group file of all five), per shard
    assert [len(batch) for batch in batches] == [2 * 6, 1 * 6]
    assert all(not record["failures"] for record in records)


def test_blender_batches_read_the_glb_without_leaf_instancing(shard_run):
    _, batches, _ = shard_run
    for item in (item for batch in batches for item in batch):
        document, _ = read_glb_chunks(open(item["glb"], "rb").read())
        assert "EXT_mesh_gpu_instancing" not in document.get("extensionsUsed", [])


def test_every_asset_record_lists_its_fbx_files_with_their_sizes(shard_run):
    out, _, _ = shard_run
    records = [json.loads(path.read_text()) for path in sorted(out.glob("assets/*/asset.json"))]
    assert len(records) == 3
    for record in records:
        fbx = {k: v for k, v in record["sizes"].items() if k.startswith("fbx_")}
        assert sorted(fbx) == sorted(f"fbx_{name}" for name in ("LOD0", "LOD1", "LOD2", "LOD3", "IMPOSTOR"))
        assert record["blender"] == "written" and all(v >= 100 for v in fbx.values())


def test_a_failed_blender_batch_keeps_every_asset_and_says_so(tmp_path, monkeypatch):
    def failing_batch(jobs, timeout=0.0):
        raise BlenderError("Blender job 'fbx' failed (exit status 1); last lines of its log:\nSegmentation fault")

    monkeypatch.setattr(job, "blender_available", lambda: True)
    monkeypatch.setattr(job, "export_fbx_batch", failing_batch)
    spec = parse_library_spec(SPEC)
    location = Location.resolve(str(tmp_path))
    write_library_record(location, spec)  # what run_library writes before the shards
    chain = job.LibraryChain(spec, str(tmp_path))
    records = [run_shard(spec, plan, location, chain) for plan in plan_shards(spec)]
    assert all(not record["failures"] for record in records)  # the trees were built; only Blender failed
    assets = [json.loads(path.read_text()) for path in sorted(tmp_path.glob("assets/*/asset.json"))]
    assert len(assets) == 3  # every asset of both shards, the shards' last ones included
    for record in assets:
        assert record["blender"] == "failed: Blender job 'fbx' failed (exit status 1); last lines of its log:"
        assert not any(key.startswith("fbx_") for key in record["files"]) and "glb" in record["files"]
    summary = write_catalog(location, spec)
    assert summary["assets"] == 3 and "FBX export failed for 3 asset(s)" in summary["blender"]
    problems = validate_library(str(tmp_path))
    assert sorted(p.path for p in problems) == sorted(str(path) for path in tmp_path.glob("assets/*/asset.json"))
    assert all("Blender outputs failed" in p.reason for p in problems)
    # The next run (a resumed `farm library`) exports the failed assets again, in one batch, and leaves the rest.
    batches = []

    def record_batch(jobs, timeout=0.0):
        batches.append(list(jobs))
        return [{"bytes": 100 + i} for i in range(len(jobs))]

    monkeypatch.setattr(job, "export_fbx_batch", record_batch)
    monkeypatch.setattr(job, "write_lod_group_node", lambda location, relative, ident, entry: 200)  # the recorder wrote no file
    glb_before = {path: path.read_bytes() for path in tmp_path.glob("assets/*/*.glb")}
    assert job.retry_failed_fbx(location, spec) == 3
    assert [len(batch) for batch in batches] == [3 * 6]
    for path in sorted(tmp_path.glob("assets/*/asset.json")):
        record = json.loads(path.read_text())
        assert record["blender"] == "written"
        assert sorted(k for k in record["files"] if k.startswith("fbx_")) == \
            sorted(f"fbx_{name}" for name in ("LOD0", "LOD1", "LOD2", "LOD3", "IMPOSTOR"))
    assert {path: path.read_bytes() for path in tmp_path.glob("assets/*/*.glb")} == glb_before
    assert validate_library(str(tmp_path)) == []
    assert job.retry_failed_fbx(location, spec) == 0 and len(batches) == 1  # nothing left to retry
