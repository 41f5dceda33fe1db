"""The asset catalogs of the library's Blender files: catalog ids, the `blender_assets.cats.txt` beside the
`.blend` files, and `.blend` libraries written and read with their assets filed under those catalogs.

In: catalog paths ("Trees/Maple") and asset dicts; out: UUIDs, the catalog file, and what
`renderers.blender_assets` (the Blender adapter) writes and reads, with each asset's catalog path.
"""
from __future__ import annotations

import fcntl
import os
import re
import uuid
from pathlib import Path
from typing import Mapping, Sequence

from renderers.blender import DEFAULT_TIMEOUT_S, BlenderError
from renderers.blender_assets import inspect_blend, write_asset_library

__all__ = ["CATALOG_FILE", "DEFAULT_CATALOG", "CATALOG_NAMESPACE", "check_catalog_path", "catalog_uuid",
           "read_catalog_file", "write_catalog_file", "write_blender_library", "inspect_blender_library"]

CATALOG_FILE = "blender_assets.cats.txt"
DEFAULT_CATALOG = "Trees"
# uuid5 namespace of treefarm's catalogs: the same catalog path gets the same UUID in every library and run.
CATALOG_NAMESPACE = uuid.UUID("6f1d6a52-3c1e-5b43-9a0e-7a3b8f0c2d11")
_CATALOG_SEGMENT = re.compile(r"^[^:/\\\n]+$")
# The file's header names the module that first wrote it; it stays as it was so the file keeps its bytes.
_HEADER = ["# This is an Asset Catalog Definition file for Blender.", "#",
           "# Empty lines and lines starting with `#` will be ignored.",
           "# The first non-ignored line should be the version indicator.",
           '# Other lines are of the format "UUID:catalog/path/for/assets:simple catalog name"',
           "# Written by treefarm (renderers/blender_assets.py).", "", "VERSION 1", ""]


def check_catalog_path(path: str) -> str:
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
    return str(uuid.uuid5(CATALOG_NAMESPACE, check_catalog_path(path)))


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
        segments = check_catalog_path(path).split("/")
        wanted.update("/".join(segments[:i]) for i in range(1, len(segments) + 1))
    lock = os.open(folder, os.O_RDONLY)  # a lock on the folder itself leaves no lock file in the library
    try:
        fcntl.flock(lock, fcntl.LOCK_EX)
        catalogs = read_catalog_file(folder)
        for path in wanted - catalogs.keys():
            catalogs[path] = catalog_uuid(path)
        lines = _HEADER + [f"{catalogs[p]}:{p}:{p.replace('/', '-')}" for p in sorted(catalogs)]
        tmp = folder / (CATALOG_FILE + ".tmp")
        tmp.write_text("\n".join(lines) + "\n")
        os.replace(tmp, folder / CATALOG_FILE)
    finally:
        os.close(lock)  # closing releases the lock
    return catalogs


def write_blender_library(assets: Sequence[Mapping], blend_path: str | Path, default_catalog: str = DEFAULT_CATALOG,
                          timeout: float = DEFAULT_TIMEOUT_S) -> dict:
    """Write one `.blend` of marked assets (`renderers.blender_assets.write_asset_library`) filed under their
    catalogs, then add those catalogs to the catalog file beside it.

    assets : the dicts `write_asset_library` takes, with catalog_path ("Trees/Maple"; `default_catalog` when
             absent) in place of catalog_id: an asset's catalog id is the one the folder's catalog file already
             gives its path, else `catalog_uuid(path)`.
    Returns `write_asset_library`'s dictionary with catalogs ({path: UUID} of the whole catalog file) and each
    asset row's catalog_path. The catalog file is written after the .blend, so a failed job leaves the folder
    as it was.
    """
    folder = Path(blend_path).resolve().parent
    known = read_catalog_file(folder)
    items, paths = [], []
    for asset in assets:
        if not isinstance(asset, Mapping):  # write_asset_library names what is wrong with it
            items.append(asset)
            continue
        path = check_catalog_path(asset.get("catalog_path") or default_catalog)
        paths.append(path)
        items.append({**{k: v for k, v in asset.items() if k != "catalog_path"},
                      "catalog_id": known.get(path) or catalog_uuid(path)})
    written = write_asset_library(items, blend_path, timeout)
    catalogs = write_catalog_file(folder, paths)
    rows = [{**row, "catalog_path": path} for row, path in zip(written["assets"], paths)]
    return {**written, "catalogs": catalogs, "assets": rows}


def inspect_blender_library(path: str | Path, timeout: float = 300.0) -> dict:
    """`renderers.blender_assets.inspect_blend` of a .blend, each asset row with its catalog_path from the
    catalog file beside it (None when the file does not list its catalog id)."""
    inspected = inspect_blend(path, timeout)
    by_uuid = {u: p for p, u in read_catalog_file(Path(path).parent).items()}
    for row in inspected["assets"]:
        row["catalog_path"] = by_uuid.get(row["catalog_id"])
    return inspected
