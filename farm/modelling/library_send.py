"""Send to library: a modelling session's tree built as a full studio asset (levels of detail, impostor, wind
data, season textures, the files the library's spec asks for, previews) into an asset library folder, through the
library's own builder, with the session file beside it; the catalog lists it beside the (species, seed) assets.

In: a ModelSession and a library folder (made by `farm library --out DIR`). Out: the asset's record; the folder's
catalog rewritten. The asset's id is "model-" and 16 hex digits of the session file's SHA-256 (same session,
same asset).
"""
from __future__ import annotations

from renderers.gl_coverage import CoverageRenderer
from species.timing import StageTimer

from ..dataset.storage import Location, sha256_hex
from ..library.asset import build_asset_from_tree
from ..library.catalog import write_catalog
from ..library.job import finish_assets, stage_asset_files
from ..library.records import read_library_spec, write_session_record
from .modelled_tree import session_mesh
from .session import ModelSession, session_to_json

__all__ = ["send_session_to_library", "session_asset_id", "SESSION_TAG"]

SESSION_TAG = "hand-modelled"


def session_asset_id(session: ModelSession) -> str:
    return f"model-{sha256_hex(session_to_json(session).encode())[:16]}"


def send_session_to_library(session: ModelSession, library: str) -> dict:
    """Build the session's tree into `library` (LibraryError when the folder is not a library; a grow error
    before anything is written); returns the asset's record (asset.json). Its files are written whole, asset.json
    last, then the catalog."""
    location = Location.resolve(library)
    spec = read_library_spec(location)
    ident = session_asset_id(session)
    params, skeleton, lod0 = session_mesh(session, name=ident)
    text = session_to_json(session).encode()
    renderer = CoverageRenderer(64)
    try:
        timer = StageTimer()
        asset = build_asset_from_tree(ident, session.preset, session.seed, params, skeleton, lod0, spec, renderer,
                                      timer)
        pending = stage_asset_files(asset, location, spec, renderer, timer)
        relative = f"{pending['folder']}/session.json"
        location.write_atomic(relative, text)
        record = pending["record"]
        record["files"]["session"] = relative
        record["sizes"]["session"] = len(text)
        record["sha256"][relative] = sha256_hex(text)
        record["all_files"] = sorted([*record["all_files"], relative])
        record["tags"] = sorted({*record["tags"], SESSION_TAG})
        record["source"] = "session"
        record = finish_assets([pending], location, spec, timer)[0]
    finally:
        renderer.close()
    write_session_record(location, ident)
    write_catalog(location, spec)
    return record
