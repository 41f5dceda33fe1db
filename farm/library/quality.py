"""Each level's silhouette IoU beside the measure's own floor (issue 26): LOD0 against LOD0 moved half a pixel.

An engine's temporal anti-aliasing jitters the camera by sub-pixel offsets every frame, so a level whose silhouette
differs from LOD0's by no more than LOD0's own half-pixel shift pops no more than LOD0 already shimmers. The floor
of a level: LOD0's coverage silhouette at the level's switch size against the same camera with its principal point
moved SHIFT_PX across, then up; the least IoU over renderers.silhouette_metric.QUALITY_AZIMUTHS (both silhouettes closed
as the library measures them). A level meets the restated target when its least IoU is at least its floor minus
FLOOR_MARGIN. `level_floors` also gives the floors of LOD0 turned by given angles (what a view-sampled impostor
shows between its views), for `benchmarks/bench_silhouette_floor.py`.

The floors cost extra renders (two per azimuth and level), so a build stores only the IoU per level;
`farm library validate DIR --quality` rebuilds each asset's LOD0 (same species, seed and spec: the same bytes),
reports floor and margin per level, and stores them (`quality/<id>.json`, read into the catalog's `iou_floor`).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from renderers.alpha_coverage import coverage_tree
from renderers.framing import framing_points
from renderers.gl_coverage import CoverageRenderer
from renderers.silhouette_metric import QUALITY_AZIMUTHS, closed_silhouette, silhouette_iou, switch_camera
from species.timing import StageTimer

from ..dataset.storage import Location
from .asset import build_asset, leaf_fractions
from .records import read_library_spec

__all__ = ["SHIFT_PX", "FLOOR_MARGIN", "LevelFloor", "level_floors", "asset_floors", "library_floors",
           "floors_record_path", "store_floors", "stored_floors", "CatalogQuality", "catalog_quality"]

SHIFT_PX = 0.5
FLOOR_MARGIN = 0.02


@dataclass(frozen=True)
class LevelFloor:
    """One level of one asset: its least IoU over the quality azimuths, its half-pixel floor, the margin."""

    asset: str
    level: str
    switch_px: int
    iou: float
    floor: float

    @property
    def margin(self) -> float:
        return self.iou - self.floor

    @property
    def meets(self) -> bool:
        return self.iou >= self.floor - FLOOR_MARGIN


@dataclass(frozen=True)
class CatalogQuality:
    """What a library's catalog says of its levels: how many assets and levels after LOD0 it lists, and each level
    whose half-pixel floor `farm library validate --quality` measured."""

    assets: int
    levels: int
    measured: tuple[LevelFloor, ...]

    def summary(self) -> str:
        """One clause for validate's line: the measured levels within the margin of their floors, or what to run."""
        if not self.measured:
            return (f"the half-pixel floors of its {self.levels} levels are not measured (`--quality` measures "
                    "them)")
        unmeasured = self.levels - len(self.measured)
        return (f"{sum(f.meets for f in self.measured)} of {len(self.measured)} levels within {FLOOR_MARGIN} of "
                f"their half-pixel floor" + (f" ({unmeasured} not measured)" if unmeasured else ""))


def catalog_quality(path: str) -> CatalogQuality:
    """The levels of a finished library folder judged against the floors stored in its catalog.json (`iou_floor`:
    null until measured); reads nothing else and renders nothing."""
    location = Location.resolve(path)
    rows = json.loads(location.read_bytes("catalog.json"))
    levels, measured = 0, []
    for row in rows:
        floors = row.get("iou_floor") or [None] * len(row["level_names"])
        for name, px, iou, floor in list(zip(row["level_names"], row["switch_px"], row["iou_min"], floors))[1:]:
            levels += 1
            if floor is not None:
                measured.append(LevelFloor(row["id"], name, int(px), float(iou), float(floor)))
    return CatalogQuality(len(rows), levels, tuple(measured))


def level_floors(renderer, cover, points, switch_px: int, turns_deg: Sequence[float] = ()) -> tuple[float, ...]:
    """(half-pixel floor, one floor per turn in `turns_deg`) of LOD0's coverage tree `cover` at `switch_px`: the
    least IoU over the quality azimuths (for the half pixel, over a move across and a move up)."""
    def silhouette(camera) -> np.ndarray:
        return closed_silhouette(renderer.coverage(cover, camera))

    shifted, turned = [], {turn: [] for turn in turns_deg}
    for azimuth in QUALITY_AZIMUTHS:
        camera = switch_camera(points, azimuth, switch_px)
        reference = silhouette(camera)
        for axis in (0, 1):  # the principal point half a pixel over, then up: the whole image moves by that much
            aside = camera.K.copy()
            aside[axis, 2] += SHIFT_PX
            shifted.append(silhouette_iou(reference, silhouette(dataclasses.replace(camera, K=aside))))
        # Seen from azimuth + t, the tree looks as if turned by -t in front of the camera of azimuth.
        for turn in turns_deg:
            turned[turn].append(silhouette_iou(reference, silhouette(switch_camera(points, azimuth + turn, switch_px))))
    return min(shifted), *(min(values) for values in turned.values())


def asset_floors(asset, renderer) -> list[LevelFloor]:
    """The floor and margin of each level after LOD0 (LOD1..LOD3, the impostor) of a built `LibraryAsset`."""
    lod0_fraction, _ = leaf_fractions(asset.leaf_atlases["summer"])
    cover = coverage_tree(asset.lod0, lod0_fraction)
    points = framing_points(asset.lod0)
    return [LevelFloor(asset.asset_id, level.name, int(level.switch_px), float(min(level.iou)),
                       float(level_floors(renderer, cover, points, level.switch_px)[0]))
            for level in asset.levels[1:]]


def library_floors(path: str, progress: bool = False) -> list[LevelFloor]:
    """Every catalogued asset of a library folder rebuilt with the library's spec and measured (`asset_floors`)."""
    from tqdm import tqdm

    location = Location.resolve(path)
    spec = read_library_spec(location)
    rows = json.loads(location.read_bytes("catalog.json")) if location.exists("catalog.json") else []
    renderer = CoverageRenderer(64)  # one EGL context for every size: the viewport follows the camera
    floors: list[LevelFloor] = []
    try:
        for row in tqdm(rows, desc="floors", unit="asset", disable=not progress):
            asset = build_asset(row["species"], int(row["seed"]), spec, renderer, StageTimer())
            floors += asset_floors(asset, renderer)
    finally:
        renderer.close()
    return floors


def floors_record_path(ident: str) -> str:
    """Where a library folder keeps the floors measured for asset `ident`."""
    return f"quality/{ident}.json"


def store_floors(location, floors: list[LevelFloor]) -> None:
    """Write each asset's measured floors (`quality/<id>.json`, atomically): per level its switch size, least IoU,
    half-pixel floor, margin and whether it meets the target, with SHIFT_PX and FLOOR_MARGIN."""
    by_asset: dict[str, dict] = {}
    for floor in floors:
        by_asset.setdefault(floor.asset, {})[floor.level] = {
            "switch_px": floor.switch_px, "iou_min": round(floor.iou, 6), "floor": round(floor.floor, 6),
            "margin": round(floor.margin, 6), "meets": bool(floor.meets)}
    for ident, levels in by_asset.items():
        record = {"id": ident, "shift_px": SHIFT_PX, "floor_margin": FLOOR_MARGIN, "levels": levels}
        location.write_atomic(floors_record_path(ident), json.dumps(record, indent=1, sort_keys=True).encode())


def stored_floors(location, ident: str) -> dict[str, float]:
    """{level name: half-pixel floor} stored for asset `ident` ({} when never measured)."""
    path = floors_record_path(ident)
    if not location.exists(path):
        return {}
    return {name: level["floor"] for name, level in json.loads(location.read_bytes(path))["levels"].items()}
