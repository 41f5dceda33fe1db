"""The asset-library job on the farm's pipeline: `LibraryChain` is a tree builder for `farm.pipeline.run_job` that
builds an asset and writes its files atomically; the driver then writes the catalog, sheets and gallery.

In: a LibrarySpec and an output folder; out: assets/<id>/..., trees/ and views/ parts (the library's trees as a
farm dataset, which also carries resume), manifest.json, library.json, catalog.parquet/.json, index.html.
"""
from __future__ import annotations

import json
import os
from functools import partial

import numpy as np

from renderers.blender import BlenderError, blender_available
from renderers.blender_assets import export_fbx_batch
from renderers.gl_coverage import CoverageRenderer
from species.meshing.gltf import z_up_to_y_up
from species.studio.collision import capsule_mesh
from species.timing import StageTimer

from ..jobs import preset_names
from ..dataset.manifest import JOB_RECORD
from ..pipeline import run_job
from ..dataset.storage import Location, sha256_hex
from ..tree_chain import BuiltTree, to_json, tree_seed
from .asset import LibraryAsset, build_asset
from .catalog import write_catalog
from .gltf_asset import asset_to_glb, glb_size
from .lod_group import lod_group_entry, lod_group_job, write_lod_group_node
from .png_cache import PngCache
from .previews import thumbnail, turntable
from .records import (ASSETS, BLENDER_FAILED, BLENDER_PENDING, LIBRARY_RECORD, LibraryError, asset_record_path,
                      library_asset_ids, read_library_spec, write_added_record, write_library_record)
from .spec import FORMATS, LibrarySpec, LibrarySpecError, species_of_trees
from .usd_asset import TEXTURE_FILES, TWIG_TEXTURE_FILES, asset_to_usdc

__all__ = ["LibraryChain", "run_library", "add_asset", "write_asset_files", "stage_asset_files", "finish_assets",
           "retry_failed_fbx", "check_fbx_blender"]


def _obj_text(part, name: str) -> bytes:
    lines = [f"# treefarm collision capsules of {name}: metres, Y up\no {name}\n"]
    lines += [f"v {x:.5f} {y:.5f} {z:.5f}\n" for x, y, z in z_up_to_y_up(part.vertices).astype(np.float64)]
    lines += [f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in part.faces]
    return "".join(lines).encode("ascii")


def write_asset_files(asset: LibraryAsset, location: Location, spec, renderer, timer: StageTimer,
                      pngs: PngCache | None = None) -> dict:
    """Write every file of one asset under assets/<id>/ (each atomically; asset.json last) and return the
    asset record: metadata plus files {kind: relative path}, sizes {kind: bytes} and sha256 {path: hex}."""
    return finish_assets([stage_asset_files(asset, location, spec, renderer, timer, pngs)], location, spec,
                         timer)[0]


def _wants_blender(spec, location: Location) -> bool:
    return bool({"fbx", "blend"} & set(spec.formats)) and "glb" in spec.formats and location.is_local \
        and blender_available()


def stage_asset_files(asset: LibraryAsset, location: Location, spec, renderer, timer: StageTimer,
                      pngs: PngCache | None = None) -> dict:
    """Write every file of one asset but its FBX files and asset.json; return the pending asset: its record
    (without FBX entries), the asset and the folder. `finish_assets` exports the FBX files of many pending
    assets in one Blender process and writes each asset.json. `pngs` encodes every texture and picture (the
    worker's cache; None: a cache for this asset)."""
    folder = f"{ASSETS}/{asset.asset_id}"
    files: dict[str, bytes] = {}
    kinds: dict[str, str] = {}

    def put(kind: str, relative: str, data: bytes) -> None:
        files[f"{folder}/{relative}"] = data
        kinds[kind] = f"{folder}/{relative}"

    sizes = {}
    pngs = PngCache() if pngs is None else pngs
    with timer.stage("textures"):
        maps = asset.bark_maps
        images = {"bark_base_color": maps.base_color, "bark_normal": maps.normal,
                  "bark_roughness_metallic": maps.roughness_metallic, "impostor_albedo": asset.impostor.albedo,
                  "impostor_normal": asset.impostor.normal,
                  **{f"leaf_atlas_{s}": image for s, image in asset.leaf_atlases.items()}}
        if "usd" in spec.formats:
            for name, relative in TEXTURE_FILES.items():
                put(f"texture_{name}", relative, pngs.encode(images[name]))
            if asset.twig_atlas is not None:
                put("texture_twig_normal", TWIG_TEXTURE_FILES["twig_normal"], pngs.encode(asset.twig_atlas.normal))
                for season, image in asset.twig_albedos.items():
                    put(f"texture_twig_atlas_{season}", TWIG_TEXTURE_FILES[f"twig_atlas_{season}"],
                        pngs.encode(image, palette=True))
    if "glb" in spec.formats:
        with timer.stage("glb"):
            put("glb", f"{asset.asset_id}.glb", asset_to_glb(asset, pngs=pngs))
            sizes["glb_without_instancing"] = glb_size(asset, instanced=False, pngs=pngs)
            if _wants_blender(spec, location):
                # Blender's input: leaves baked, not instanced (it imports instanced leaves far slower, and FBX
                # has no instancing an engine reads anyway).
                put("glb_flat", f"blender/{asset.asset_id}_flat.glb",
                    asset_to_glb(asset, instanced=False, pngs=pngs))
    if "usd" in spec.formats:
        with timer.stage("usd"):
            put("usd", f"{asset.asset_id}.usdc", asset_to_usdc(asset))
    if "obj" in spec.formats:
        with timer.stage("obj"):
            # Side files keyed by their own name (stable keys); textures at the library's fast zlib level.
            for name, data in asset.lod0.to_obj(pngs.compress_level).items():
                put("obj" if name.endswith(".obj") else f"obj_{name}", f"obj/{name}", data)
    if "collision" in spec.formats:
        put("collision", f"{asset.asset_id}_collision.obj", _obj_text(capsule_mesh(asset.capsules),
                                                                       f"{asset.asset_id}_collision"))
    with timer.stage("previews"):
        put("thumbnail", "thumbnail.png", pngs.encode(thumbnail(renderer, asset.lod0)))
        put("turntable", "turntable.png", pngs.encode(turntable(renderer, asset.lod0)))
    with timer.stage("write"):
        for relative, data in files.items():
            location.write_atomic(relative, data)
    record = asset.metadata()
    record.update({"files": {k: v for k, v in kinds.items() if not k.startswith(("texture_", "obj_"))},
                   "all_files": sorted(files),
                   "sizes": {**{k: len(files[v]) for k, v in kinds.items() if v in files}, **sizes},
                   "sha256": {path: sha256_hex(data) for path, data in sorted(files.items())},
                   "tags": _tags(asset), "blender": "not asked"})
    if asset.impostor.layout():  # an octahedral impostor (the crossed planes record nothing)
        record["impostor"] = asset.impostor.layout()
    if "fbx" in spec.formats:
        record["blender"] = "pending" if "glb_flat" in kinds else BLENDER_PENDING
    return {"record": record, "level_names": [lv.name for lv in asset.levels], "folder": folder}


def finish_assets(pending: list[dict], location: Location, spec, timer: StageTimer) -> list[dict]:
    """Export the FBX files (one per LOD, and the LOD-group file of every level, `lod_group`) of every pending
    asset in ONE Blender process, from each asset's non-instanced GLB, then write each asset.json (atomically,
    last); returns the finished records.

    When Blender fails, every asset of the batch still gets its asset.json (its other files are whole), with
    `"blender": "failed: <Blender's message>"`; the catalog counts those assets and `farm library validate`
    names them."""
    jobs, owners = [], []
    for index, item in enumerate(pending):
        record = item["record"]
        if "fbx" not in spec.formats or "glb_flat" not in record["files"]:
            continue
        ident = record["id"]
        for name in item["level_names"]:
            jobs.append({"glb": location.path(record["files"]["glb_flat"]),
                         "fbx": location.path(f"{item['folder']}/fbx/{ident}_{name}.fbx"),
                         "node": f"{ident}_{name}", "name": f"{ident}_{name}",
                         **({"animated": True} if spec.skeletal_wind else {})})
            owners.append((index, name))
        jobs.append(lod_group_job(record, location, item["folder"]))  # every level in one file, last
        owners.append((index, None))
    if jobs:
        try:
            with timer.stage("blender"):
                rows = export_fbx_batch(jobs)
        except BlenderError as exc:
            rows, failure = [], f"{BLENDER_FAILED}{str(exc).splitlines()[0]}"
            for index in {index for index, _ in owners}:
                pending[index]["record"]["blender"] = failure
        for (index, name), job, row in zip(owners, jobs, rows):
            record = pending[index]["record"]
            relative = os.path.relpath(job["fbx"], location.root)
            key = "fbx" if name is None else f"fbx_{name}"  # None: the LOD-group file
            record["files"][key] = relative
            record["sizes"][key] = int(row["bytes"])
            if name is None:  # Blender's exporter cannot write the LodGroup node: added to its file here
                record["lod_group"] = lod_group_entry(record)
                record["sizes"][key] = write_lod_group_node(location, relative, record["id"], record["lod_group"])
            record["all_files"] = sorted([*record["all_files"], relative])
            record["blender"] = "written"
    for item in pending:
        location.write_atomic(asset_record_path(item["record"]["id"]), to_json(item["record"]).encode())
    return [item["record"] for item in pending]


def retry_failed_fbx(location: Location, spec, timer: StageTimer | None = None) -> int:
    """Export again, in one Blender process, the FBX files of every asset whose export failed (asset.json says
    `"blender": "failed: ..."`), as a resumed job should finish what a run left undone; returns how many assets
    were retried. Their other files are whole and stay as they are; each asset.json is rewritten (atomically)
    with the new outcome."""
    if "fbx" not in spec.formats or not _wants_blender(spec, location):
        return 0
    pending = []
    for ident in library_asset_ids(location, spec):
        path = asset_record_path(ident)
        if not location.exists(path):
            continue
        record = json.loads(location.read_bytes(path))
        if str(record.get("blender", "")).startswith(BLENDER_FAILED) and "glb_flat" in record["files"] \
                and location.exists(record["files"]["glb_flat"]):
            pending.append({"record": record, "level_names": [level["name"] for level in record["levels"]],
                            "folder": f"{ASSETS}/{ident}"})
    if pending:
        finish_assets(pending, location, spec, timer or StageTimer())
    return len(pending)


def check_fbx_blender(spec: LibrarySpec) -> None:
    """Refuse (LibrarySpecError naming `formats`) a spec that names `fbx` among its formats when Blender, which
    writes the FBX files, is missing. The default formats (every format) still build there, their FBX files
    left pending in asset.json, so the default library builds on any machine."""
    if "fbx" in spec.formats and tuple(spec.formats) != FORMATS and not blender_available():
        raise LibrarySpecError("formats", list(spec.formats), "formats without 'fbx' on this machine: Blender, which "
                               "writes the FBX files, is missing (run `make env`, or set $TREEFARM_BLENDER_PYTHON)")


def _tags(asset: LibraryAsset) -> list[str]:
    height = asset.skeleton.height
    size = "small" if height < 4 else "medium" if height < 15 else "large"
    return sorted({asset.species, asset.generator, size, "leafless" if asset.skeleton.n_leaves == 0 else "leafy"})


class LibraryChain:
    """A farm tree builder: one asset per call, files written as a side effect, the tree returned for the
    pipeline's trees table. One CoverageRenderer and one PngCache per worker process. The Blender outputs of a
    shard's assets are made together, in one Blender process, when the shard's last tree has been built."""

    def __init__(self, spec: LibrarySpec, out: str) -> None:
        self.spec, self.location = spec, Location.resolve(out)
        self._renderer = None
        self._pngs = PngCache()
        self._pending: list[dict] = []
        names = species_of_trees(spec)
        size = spec.shard_size
        # (species, seed) of each shard's last tree: the pipeline builds a shard's trees in index order.
        self._shard_ends = {(names[i], tree_seed(spec.seed, i)) for i in range(len(names))
                            if i % size == size - 1 or i == len(names) - 1}

    def renderer(self):
        if self._renderer is None:
            self._renderer = CoverageRenderer(64)
        return self._renderer

    def __call__(self, species_name: str, seed: int, timer: StageTimer) -> BuiltTree:
        try:
            asset = build_asset(species_name, seed, self.spec, self.renderer(), timer)
            self._pending.append(stage_asset_files(asset, self.location, self.spec, self.renderer(), timer,
                                                   self._pngs))
        finally:  # a failed last tree still finishes the shard's other assets
            if (species_name, seed) in self._shard_ends:
                pending, self._pending = self._pending, []
                finish_assets(pending, self.location, self.spec, timer)
        return BuiltTree(params=asset.params, skeleton=asset.skeleton, mesh=asset.lod0)


def run_library(spec: LibrarySpec, out: str, workers: int | None = None, address: str | None = None,
                progress: bool = True) -> dict:
    """Run (or resume) a library job into `out` on the farm pipeline, then write the catalog; returns it."""
    location = Location.resolve(out)
    check_fbx_blender(spec)
    if location.exists(LIBRARY_RECORD):
        existing = json.loads(location.read_bytes(LIBRARY_RECORD))
        if existing.get("spec_digest") != spec.digest():
            raise LibraryError(f"{location.uri} holds a library of another spec; write this one to another --out")
    elif location.exists(JOB_RECORD):
        # Checked before library.json is written: a refused run must leave the folder as it was.
        raise LibraryError(f"{location.uri} holds a farm job, not a library; write the library to another --out")
    write_library_record(location, spec)
    manifest = run_job(spec, out, workers=workers, address=address,
                       builder_factory=partial(LibraryChain, out=location.uri), progress=progress)
    retry_failed_fbx(location, spec)  # a run whose Blender batch failed is finished by the next one
    catalog = write_catalog(location, spec)
    return {"manifest": manifest, "catalog": catalog}


def add_asset(out: str, species_name: str, seed: int) -> dict:
    """Build one more asset (species, tree seed) into an existing library with its spec; rewrite the catalog."""
    location = Location.resolve(out)
    spec = read_library_spec(location)
    check_fbx_blender(spec)
    known = preset_names()
    if species_name not in known:
        raise LibraryError(f"species {species_name!r} is unknown: allowed {', '.join(sorted(known))}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise LibraryError(f"seed {seed!r} is invalid: allowed an integer in [0, 2^63)")
    renderer = CoverageRenderer(64)
    try:
        timer = StageTimer()
        asset = build_asset(species_name, seed, spec, renderer, timer)
        record = write_asset_files(asset, location, spec, renderer, timer)
    finally:
        renderer.close()
    write_added_record(location, species_name, seed)
    write_catalog(location, spec)
    return record
