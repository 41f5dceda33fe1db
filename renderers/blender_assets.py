"""Blender outputs of the studio asset library: FBX files per LOD and `.blend` asset libraries, via the worker.

In: GLB files (and preview PNGs); out: FBX files (Y up, metres, textures embedded) and one `.blend` of marked
assets with previews, tags and catalog ids; `inspect_blend`/`read_fbx` read them back. Which catalog an asset is
filed under, and the catalog file beside a `.blend`, are the asset library's (`farm.library.blender_catalog`).
"""
from __future__ import annotations

import tempfile
import time
import uuid
from pathlib import Path
from typing import Mapping, Sequence

from .blender import DEFAULT_TIMEOUT_S, BlenderError, run_job

__all__ = ["export_fbx", "export_fbx_batch", "write_asset_library", "inspect_blend", "read_fbx"]


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
        extra = {k: job[k] for k in ("name", "node", "animated", "nodes", "names") if job.get(k) is not None}
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
    or dicts {glb, fbx, name, node, animated (armatures and actions too)} (or {glb, fbx, nodes, names}: several
    nodes in one file, each renamed). Consecutive jobs on the same GLB import it once (one FBX per LOD node).
    Returns one `export_fbx` dictionary per job, in order; the first failure raises BlenderError."""
    if not jobs:
        raise BlenderError("export_fbx_batch needs at least one (glb_path, out_path) job; got none")
    items = [_fbx_item(job, i) for i, job in enumerate(jobs)]
    with tempfile.TemporaryDirectory(prefix="treefarm-fbx-") as tmp:
        result = run_job("fbx", {"exports": items}, tmp, timeout)
    return [_fbx_row(row) for row in result["exports"]]


def read_fbx(fbx_path: str | Path, timeout: float = 300.0) -> dict:
    """What Blender's FBX importer sees: objects (name, part, vertices, triangles, materials), triangles,
    vertices, bounds ((2, 3) metres, Z up), textures (image names), the scene's unit scale, armatures (name,
    bones), actions (name, frames, seconds) and the frame rate."""
    path = Path(fbx_path)
    if not path.is_file():
        raise BlenderError(f"fbx {str(path)!r} does not exist")
    with tempfile.TemporaryDirectory(prefix="treefarm-fbx-info-") as tmp:
        return run_job("fbx_info", {"fbx": str(path.resolve())}, tmp, timeout)


# ------------------------------------------------------------------------------------------- .blend
def _check_catalog_id(value, asset_id: str) -> str:
    """A catalog id as Blender stores it: the UUID string, as given."""
    try:
        uuid.UUID(str(value))
    except ValueError:
        raise BlenderError(f"asset {asset_id!r}: catalog_id {value!r} must be a UUID string such as "
                           f"'{uuid.UUID(int=0)}' (the id of the catalog the asset is filed under)") from None
    return str(value)


def _asset_item(asset: Mapping, index: int) -> dict:
    if not isinstance(asset, Mapping):
        raise BlenderError(f"asset {index} = {asset!r} must be a dict with id, glb_path, tags, catalog_id, ...")
    asset_id = asset.get("id")
    if not isinstance(asset_id, str) or not asset_id.strip() or len(asset_id) > 60:
        raise BlenderError(f"asset {index}: id {asset_id!r} must be a non-empty string of at most 60 characters "
                           f"(Blender's name limit is 63 bytes)")
    tags = asset.get("tags", [])
    if isinstance(tags, str) or not all(isinstance(t, str) and t for t in tags):
        raise BlenderError(f"asset {asset_id!r}: tags {tags!r} must be a list of non-empty strings")
    item = {"id": asset_id, "glb": _check_glb(asset.get("glb_path", ""), f"asset {asset_id!r}: glb_path"),
            "tags": list(tags), "description": str(asset.get("description", "")),
            "catalog_id": _check_catalog_id(asset.get("catalog_id"), asset_id)}
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


def write_asset_library(assets: Sequence[Mapping], out_blend_path: str | Path,
                        timeout: float = DEFAULT_TIMEOUT_S) -> dict:
    """Write one `.blend` whose assets Blender's Asset Browser lists.

    assets : dicts with id (unique, becomes the asset's name), glb_path (a GLB; `node` picks one glTF node's
             subtree, e.g. "LOD0"), catalog_id (the UUID of the catalog the asset is filed under; Blender names
             catalogs in a `blender_assets.cats.txt` beside the file, which this does not write), preview_png
             (optional; 256-512 px; without it a preview is drawn from the mesh), tags (list of str),
             description, and optionally author, license, copyright and properties (JSON-able custom props).
    Each asset is a collection (the GLB's objects, parts kept apart) marked as an asset with its preview,
    tags, description and catalog id. Returns blend, bytes, assets (id, catalog_id, triangles, objects,
    preview_generated, seconds), save_seconds and seconds (whole call, Blender start-up included).
    """
    start = time.perf_counter()
    if not assets:
        raise BlenderError("write_asset_library needs at least one asset; got none")
    out = Path(out_blend_path)
    if out.suffix != ".blend":
        raise BlenderError(f"library path {str(out)!r} must end in .blend")
    items = [_asset_item(asset, i) for i, asset in enumerate(assets)]
    ids = [item["id"] for item in items]
    if len(set(ids)) != len(ids):
        raise BlenderError(f"asset ids must be unique in one library; repeated: "
                           f"{sorted({i for i in ids if ids.count(i) > 1})}")
    out = out.resolve()
    with tempfile.TemporaryDirectory(prefix="treefarm-blend-") as tmp:
        result = run_job("asset_library", {"blend": str(out), "assets": items}, tmp, timeout)
    rows = [{**row, "catalog_id": item["catalog_id"]} for item, row in zip(items, result["assets"])]
    return {"blend": str(out), "bytes": result["bytes"], "assets": rows, "save_seconds": result["save_seconds"],
            "seconds": time.perf_counter() - start}


def inspect_blend(path: str | Path, timeout: float = 300.0) -> dict:
    """The assets of a .blend as Blender reads them: per asset name, type ("collections", "objects", ...),
    catalog_id, tags, description, author, properties (custom properties), preview_size, has_preview (a preview
    with visible pixels), preview_mean_rgba (values in [0, 1]), objects (meshes), object_count (empties too),
    triangles and bounds ((2, 3) metres, as an instance places them); and the file's objects and collections
    counts."""
    path = Path(path)
    if not path.is_file():
        raise BlenderError(f"blend {str(path)!r} does not exist")
    with tempfile.TemporaryDirectory(prefix="treefarm-blend-info-") as tmp:
        return run_job("blend_info", {"blend": str(path.resolve())}, tmp, timeout)
