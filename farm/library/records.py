"""What a library folder records about itself: `library.json` (the spec it was made with), where each asset's
`asset.json` lives, the assets `farm library add` added, and how an `asset.json` states its Blender outcome.

In: a library Location (and its LibrarySpec); out: those records written or read, and the ids of the assets the
library holds. The job (`job.py`) and the catalog (`catalog.py`) both read the folder through this module.
"""
from __future__ import annotations

import json

from species.errors import TreefarmError

from ..dataset import read_format_json
from ..dataset.storage import Location
from ..tree_chain import to_json, tree_seed
from .asset import asset_id
from .spec import LibrarySpec, library_spec_from_record, species_of_trees

__all__ = ["LibraryError", "LIBRARY_RECORD", "ASSETS", "ADDED", "BLENDER_PENDING", "BLENDER_FAILED",
           "asset_record_path", "write_library_record", "read_library_spec", "write_added_record",
           "library_asset_ids", "write_session_record"]

LIBRARY_RECORD = "library.json"
LIBRARY_FORMAT = "treefarm-library"  # library.json's "format"
ASSETS = "assets"
ADDED = "_added"  # one {species, seed} record per asset `farm library add` built, {id, source} per session asset
BLENDER_PENDING = "blender outputs pending (renderers.blender_assets is not available)"
BLENDER_FAILED = "failed: "  # how an asset.json's "blender" starts when its FBX export failed


class LibraryError(TreefarmError):
    """A folder that is not a library, or an asset that cannot be added."""


def asset_record_path(ident: str) -> str:
    """The relative path of an asset's record, written last of its files."""
    return f"{ASSETS}/{ident}/asset.json"


def write_library_record(location: Location, spec: LibrarySpec) -> None:
    """Write library.json: the spec and its digest (a run into a folder of another spec is refused)."""
    location.write_atomic(LIBRARY_RECORD, json.dumps({"format": LIBRARY_FORMAT, "spec": spec.to_dict(),
                                                      "spec_digest": spec.digest()}, indent=1).encode())


def read_library_spec(location: Location) -> LibrarySpec:
    """The LibrarySpec a library folder was made with; LibraryError when the folder is not a library."""
    record = read_format_json(location, LIBRARY_RECORD, LIBRARY_FORMAT, error=LibraryError,
                              hint="it is not an asset library; make one with `farm library --out DIR`")
    return library_spec_from_record(record["spec"])


def write_added_record(location: Location, species_name: str, seed: int) -> None:
    """Record that `farm library add` built the asset of (species, tree seed), so the catalog lists it."""
    location.write_atomic(f"{ADDED}/{asset_id(species_name, seed)}.json",
                          to_json({"species": species_name, "seed": seed}).encode())


def write_session_record(location: Location, ident: str) -> None:
    """Record that an asset was built from a modelling session (`farm model`'s send to library), so the catalog
    lists it beside the (species, seed) ones."""
    location.write_atomic(f"{ADDED}/{ident}.json", to_json({"id": ident, "source": "session"}).encode())


def library_asset_ids(location: Location, spec: LibrarySpec) -> list[str]:
    """Sorted ids of every asset a library holds or should hold: its spec's trees and those `farm library add`
    added (whether or not their asset.json was written)."""
    ids = [asset_id(name, tree_seed(spec.seed, i)) for i, name in enumerate(species_of_trees(spec))]
    for name in location.list(ADDED):
        if name.endswith(".json") and not name.startswith("."):
            added = json.loads(location.read_bytes(f"{ADDED}/{name}"))
            ids.append(added["id"] if "id" in added else asset_id(added["species"], added["seed"]))
    return sorted(set(ids))
