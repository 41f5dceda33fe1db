"""Blender outputs of the studio asset library: FBX files per LOD and `.blend` asset libraries, via the worker.

In: GLB files (and preview PNGs); out: FBX files (Y up, metres, textures embedded), one `.blend` of marked assets
with previews, tags and catalogs plus the folder's `blender_assets.cats.txt`; `inspect_blend`/`read_fbx` read back.
"""
from __future__ import annotations

import fcntl
import os
import re
import tempfile
import time
import uuid
from pathlib import Path
from typing import Mapping, Sequence

from .blender import BlenderError, run_job

__all__ = ["export_fbx", "export_fbx_batch", "write_asset_library", "inspect_blend", "read_fbx", "catalog_uuid",
           "read_catalog_file", "write_catalog_file", "time_blender_outputs", "CATALOG_FILE", "DEFAULT_CATALOG"]

CATALOG_FILE = "blender_assets.cats.txt"
DEFAULT_CATALOG = "Trees"
# uuid5 namespace of treefarm's catalogs: the same catalog path gets the same UUID in every library and run.
CATALOG_NAMESPACE = uuid.UUID("6f1d6a52-3c1e-5b43-9a0e-7a3b8f0c2d11")
_CATALOG_SEGMENT = re.compile(r"^[^:/\\\n]+$")
_GLB_MAGIC = b"glTF"
DEFAULT_TIMEOUT_S = 1800.0


# ------------------------------------------------------------------------------------------- catalogs
def _check_catalog_path(path: str) -> str:
    """'Trees/Maple' style path, stripped; segments non-empty and free of ':', '\\' and newlines."""
    if not isinstance(path, str) or not path.strip():
        raise BlenderError(f"catalog path {path!r} must be a non-empty string such as 'Trees/Maple'")
    segments = [s.strip() for s in path.strip().strip("/").split("/")]
    if not all(_CATALOG_SEGMENT.match(s) for s in segments):
        raise BlenderError(f"catalog path {path!r} is not allowed: segments separated by '/', "
                           f"each non-empty and without ':', '\\\\' or newlines")
    return "/".join(segments)


def catalog_uuid(path: str) -> str:
    """The UUID string of a catalog path (uuid5 of the path: stable across runs and libraries)."""
    return str(uuid.uuid5(CATALOG_NAMESPACE, _check_catalog_path(path)))


def read_catalog_file(folder: str | Path) -> dict[str, str]:
    """{catalog path: UUID} of `folder/blender_assets.cats.txt`; {} when there is none."""
    path = Path(folder) / CATALOG_FILE
    if not path.is_file():
        return {}
    catalogs = {}
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#") or line.startswith("VERSION"):
            continue
        parts = line.split(":")
        if len(parts) != 3:
            raise BlenderError(f"{path}:{number}: {line!r} is not 'UUID:catalog/path:simple name'")
        catalogs[parts[1]] = parts[0]
    return catalogs


def write_catalog_file(folder: str | Path, paths: Sequence[str]) -> dict[str, str]:
    """Add `paths` (and their parents) to the folder's catalog definition file; returns {path: UUID} of all.

    Several libraries share one folder (one .blend per species), so the file is merged under a lock and
    replaced whole; entries already there keep their UUIDs. Lines are sorted: same catalogs, same bytes.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    wanted = set()
    for path in paths:
        segments = _check_catalog_path(path).split("/")
        wanted.update("/".join(segments[:i]) for i in range(1, len(segments) + 1))
    lock = os.open(folder, os.O_RDONLY)  # a lock on the folder itself leaves no lock file in the library
    try:
        fcntl.flock(lock, fcntl.LOCK_EX)
        catalogs = read_catalog_file(folder)
        for path in wanted - catalogs.keys():
            catalogs[path] = catalog_uuid(path)
        lines = ["# This is an Asset Catalog Definition file for Blender.", "#",
                 "# Empty lines and lines starting with `#` will be ignored.",
                 "# The first non-ignored line should be the version indicator.",
                 '# Other lines are of the format "UUID:catalog/path/for/assets:simple catalog name"',
                 "# Written by treefarm (renderers/blender_assets.py).", "", "VERSION 1", ""]
        lines += [f"{catalogs[p]}:{p}:{p.replace('/', '-')}" for p in sorted(catalogs)]
        tmp = folder / (CATALOG_FILE + ".tmp")
        tmp.write_text("\n".join(lines) + "\n")
        os.replace(tmp, folder / CATALOG_FILE)
    finally:
        os.close(lock)  # closing releases the lock
    return catalogs


# ------------------------------------------------------------------------------------------- inputs
def _check_glb(path: str | Path, what: str) -> str:
    """Absolute path of an existing file; the GLB magic itself is checked by the worker (its log shows it)."""
    path = Path(path)
    if not path.is_file():
        raise BlenderError(f"{what} {str(path)!r} does not exist: give the path of a .glb file")
    return str(path.resolve())


def _fbx_item(job, index: int) -> dict:
    if isinstance(job, Mapping):
        glb, out = job.get("glb"), job.get("fbx")
        extra = {k: job[k] for k in ("name", "node") if job.get(k) is not None}
    elif isinstance(job, (tuple, list)) and len(job) == 2:
        (glb, out), extra = job, {}
    else:
        raise BlenderError(f"FBX job {index} = {job!r} must be (glb_path, out_path) or a dict with glb, fbx, "
                           f"name, node")
    if glb is None or out is None:
        raise BlenderError(f"FBX job {index} = {job!r} needs both a GLB path and an FBX path")
    out = Path(out)
    if out.suffix.lower() != ".fbx":
        raise BlenderError(f"FBX output {str(out)!r} must end in .fbx")
    return {"glb": _check_glb(glb, f"FBX job {index}: glb"), "fbx": str(out.resolve()), **extra}


def _fbx_row(row: dict) -> dict:
    return {"fbx": row["fbx"], "glb": row["glb"], "triangles": row["triangles"],
            "triangles_per_object": {o["name"]: o["triangles"] for o in row["objects"]},
            "objects": row["objects"], "bounds": row["bounds"], "bytes": row["bytes"], "seconds": row["seconds"]}


# ------------------------------------------------------------------------------------------- FBX
def export_fbx(glb_path: str | Path, out_path: str | Path, *, name: str | None = None, node: str | None = None,
               timeout: float = DEFAULT_TIMEOUT_S) -> dict:
    """Export one GLB (or the subtree of its glTF node `node`, e.g. one LOD) as an FBX for Unity/Unreal.

    Y up, -Z forward, transforms baked, 1 unit = 1 m (UnitScaleFactor 100), textures embedded; `name` renames
    the top node (its children become `name_<child>`). Returns fbx, glb, triangles (total),
    triangles_per_object {name: count}, objects (name, part, vertices, triangles, materials), bounds
    ((2, 3) metres, Z up), bytes and seconds (in Blender, without its start-up).
    """
    job = {"glb": glb_path, "fbx": out_path, "name": name, "node": node}
    return export_fbx_batch([job], timeout=timeout)[0]


def export_fbx_batch(jobs: Sequence, timeout: float = DEFAULT_TIMEOUT_S) -> list[dict]:
    """Export many GLBs in ONE Blender process (start-up is paid once); jobs are (glb_path, out_path) pairs
    or dicts {glb, fbx, name, node}. Consecutive jobs on the same GLB import it once (one FBX per LOD node).
    Returns one `export_fbx` dictionary per job, in order; the first failure raises BlenderError."""
    if not jobs:
        raise BlenderError("export_fbx_batch needs at least one (glb_path, out_path) job; got none")
    items = [_fbx_item(job, i) for i, job in enumerate(jobs)]
    with tempfile.TemporaryDirectory(prefix="treefarm-fbx-") as tmp:
        result = run_job("fbx", {"exports": items}, tmp, timeout)
    return [_fbx_row(row) for row in result["exports"]]


def read_fbx(fbx_path: str | Path, timeout: float = 300.0) -> dict:
    """What Blender's FBX importer sees: objects (name, part, vertices, triangles, materials), triangles,
    vertices, bounds ((2, 3) metres, Z up), textures (image names) and the scene's unit scale."""
    path = Path(fbx_path)
    if not path.is_file():
        raise BlenderError(f"fbx {str(path)!r} does not exist")
    with tempfile.TemporaryDirectory(prefix="treefarm-fbx-info-") as tmp:
        return run_job("fbx_info", {"fbx": str(path.resolve())}, tmp, timeout)


# ------------------------------------------------------------------------------------------- .blend
def _asset_item(asset: Mapping, index: int, default_catalog: str) -> dict:
    if not isinstance(asset, Mapping):
        raise BlenderError(f"asset {index} = {asset!r} must be a dict with id, glb_path, tags, catalog_path, ...")
    asset_id = asset.get("id")
    if not isinstance(asset_id, str) or not asset_id.strip() or len(asset_id) > 60:
        raise BlenderError(f"asset {index}: id {asset_id!r} must be a non-empty string of at most 60 characters "
                           f"(Blender's name limit is 63 bytes)")
    tags = asset.get("tags", [])
    if isinstance(tags, str) or not all(isinstance(t, str) and t for t in tags):
        raise BlenderError(f"asset {asset_id!r}: tags {tags!r} must be a list of non-empty strings")
    item = {"id": asset_id, "glb": _check_glb(asset.get("glb_path", ""), f"asset {asset_id!r}: glb_path"),
            "tags": list(tags), "description": str(asset.get("description", "")),
            "catalog_path": _check_catalog_path(asset.get("catalog_path") or default_catalog)}
    preview = asset.get("preview_png")
    if preview:
        if not Path(preview).is_file():
            raise BlenderError(f"asset {asset_id!r}: preview_png {str(preview)!r} does not exist "
                               f"(leave it out to have a preview drawn from the mesh)")
        item["preview_png"] = str(Path(preview).resolve())
    for key in ("node", "author", "license", "copyright", "properties"):
        if asset.get(key) is not None:
            item[key] = asset[key]
    return item


def write_asset_library(assets: Sequence[Mapping], out_blend_path: str | Path, catalog_name: str = DEFAULT_CATALOG,
                        timeout: float = DEFAULT_TIMEOUT_S) -> dict:
    """Write one `.blend` whose assets Blender's Asset Browser lists, and the folder's catalog file.

    assets : dicts with id (unique, becomes the asset's name), glb_path (a GLB; `node` picks one glTF node's
             subtree, e.g. "LOD0"), preview_png (optional; 256-512 px; without it a preview is drawn from the
             mesh), tags (list of str), catalog_path ("Trees/Maple"; `catalog_name` when absent),
             description, and optionally author, license, copyright and properties (JSON-able custom props).
    Each asset is a collection (the GLB's objects, parts kept apart) marked as an asset with its preview,
    tags, description and catalog UUID (`catalog_uuid(path)`, listed in blender_assets.cats.txt beside the
    .blend). Returns blend, bytes, catalogs {path: UUID}, assets (id, catalog_path, catalog_id, triangles,
    objects, preview_generated, seconds), save_seconds and seconds (whole call, Blender start-up included).
    """
    start = time.perf_counter()
    if not assets:
        raise BlenderError("write_asset_library needs at least one asset; got none")
    out = Path(out_blend_path)
    if out.suffix != ".blend":
        raise BlenderError(f"library path {str(out)!r} must end in .blend")
    items = [_asset_item(asset, i, catalog_name) for i, asset in enumerate(assets)]
    ids = [item["id"] for item in items]
    if len(set(ids)) != len(ids):
        raise BlenderError(f"asset ids must be unique in one library; repeated: "
                           f"{sorted({i for i in ids if ids.count(i) > 1})}")
    out = out.resolve()
    known = read_catalog_file(out.parent)
    for item in items:
        item["catalog_id"] = known.get(item["catalog_path"]) or catalog_uuid(item["catalog_path"])
    with tempfile.TemporaryDirectory(prefix="treefarm-blend-") as tmp:
        result = run_job("asset_library", {"blend": str(out), "assets": items}, tmp, timeout)
    # Written after the .blend, so a failed job leaves the folder as it was.
    catalogs = write_catalog_file(out.parent, [item["catalog_path"] for item in items])
    rows = [{**row, "catalog_path": item["catalog_path"], "catalog_id": item["catalog_id"]}
            for item, row in zip(items, result["assets"])]
    return {"blend": str(out), "bytes": result["bytes"], "catalogs": catalogs, "assets": rows,
            "save_seconds": result["save_seconds"], "seconds": time.perf_counter() - start}


def inspect_blend(path: str | Path, timeout: float = 300.0) -> dict:
    """The assets of a .blend as Blender reads them: per asset name, type ("collections", "objects", ...),
    catalog_id, catalog_path (from the cats file beside it; None when not listed), tags, description, author,
    properties (custom properties), preview_size, has_preview (a preview with visible pixels),
    preview_mean_rgba (values in [0, 1]), objects (meshes), object_count (empties too), triangles and bounds
    ((2, 3) metres, as an instance places them); and the file's objects and collections counts."""
    path = Path(path)
    if not path.is_file():
        raise BlenderError(f"blend {str(path)!r} does not exist")
    with tempfile.TemporaryDirectory(prefix="treefarm-blend-info-") as tmp:
        result = run_job("blend_info", {"blend": str(path.resolve())}, tmp, timeout)
    by_uuid = {u: p for p, u in read_catalog_file(path.parent).items()}
    for row in result["assets"]:
        row["catalog_path"] = by_uuid.get(row["catalog_id"])
    return result


# ------------------------------------------------------------------------------------------- timing
def time_blender_outputs(n_assets: int, preset: str = "balsam_fir", seed: int = 0) -> dict:
    """Seconds for the Blender outputs of `n_assets` grown trees: Blender's start-up (wall time of the FBX batch
    less the time its exports took inside Blender), per FBX (one batch) and per asset of one `.blend` library
    (save included); for benchmarks, not tests."""
    import numpy as np

    import species

    if n_assets < 1:
        raise BlenderError(f"n_assets {n_assets} must be >= 1")
    with tempfile.TemporaryDirectory(prefix="treefarm-bench-blender-") as tmp:
        tmp = Path(tmp)
        glbs, triangles = [], []
        for i, child in enumerate(np.random.SeedSequence(seed).spawn(n_assets)):
            params = species.sample(preset, np.random.default_rng(child))
            _, mesh = species.rebuild(params)
            glbs.append(tmp / f"tree_{i:03d}.glb")
            glbs[-1].write_bytes(mesh.to_glb())
            triangles.append(len(mesh.bark.faces) + len(mesh.leaves.faces))
        t0 = time.perf_counter()
        rows = export_fbx_batch([(g, tmp / f"{g.stem}.fbx") for g in glbs])
        fbx_wall = time.perf_counter() - t0
        fbx_inside = sum(r["seconds"] for r in rows)
        library = write_asset_library([{"id": g.stem, "glb_path": g, "tags": ["bench"], "catalog_path": "Bench"}
                                       for g in glbs], tmp / "bench.blend")
        library_inside = sum(r["seconds"] for r in library["assets"]) + library["save_seconds"]
        return {"n_assets": n_assets, "preset": preset, "triangles_mean": float(np.mean(triangles)),
                "startup_seconds": fbx_wall - fbx_inside, "fbx_seconds_each": fbx_inside / n_assets,
                "fbx_batch_seconds": fbx_wall, "asset_seconds_each": library_inside / n_assets,
                "library_seconds": library["seconds"], "blend_bytes": library["bytes"],
                "fbx_bytes_mean": float(np.mean([r["bytes"] for r in rows]))}
