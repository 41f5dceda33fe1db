"""Test helper: a new library folder of a spec holding one asset, built by `farm library add` (no Ray).

`one_asset_library(folder, spec, species, seed) -> Path` returns the asset's folder (`assets/<id>/`).
"""
from __future__ import annotations

from pathlib import Path

from farm.dataset.storage import Location
from farm.library.job import add_asset
from farm.library.records import write_library_record
from farm.library.spec import parse_library_spec


def one_asset_library(folder: Path, spec: dict, species: str, seed: int) -> Path:
    """The folder of the asset of `species` grown from tree seed `seed` in a new library of `spec` at `folder`."""
    write_library_record(Location.resolve(str(folder)), parse_library_spec(spec))
    add_asset(str(folder), species, seed)
    return next(folder.glob("assets/*/asset.json")).parent
