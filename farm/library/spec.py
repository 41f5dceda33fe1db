"""Library job specifications: species and variants, LOD budgets and switch sizes, formats, texture size.

Input: a YAML mapping (or none: every preset, 4 variants each); output: a frozen `LibrarySpec`, a
`farm.jobs.PipelineSpec` the farm's pipeline plans and runs (same planner, seeds, shards and resume), or a
`LibrarySpecError` naming the field.
"""
from __future__ import annotations

import hashlib
import json
import math
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from farm.jobs import (DatasetTables, JobSpecError, PipelineSpec, check_int, check_keys, check_resources, check_seed,
                       load_spec, preset_names, species_of_trees)
from renderers.octahedral_impostor import FRAMES_RANGE, MAX_ATLAS_PX, OCTAHEDRAL_FRAMES
from species.studio.skeletal_wind import JOINT_BUDGET_RANGE, TRUNK_SEGMENTS, WindClipSettings

__all__ = ["LibrarySpec", "LibrarySpecError", "parse_library_spec", "load_library_spec", "default_library_spec",
           "library_spec_from_record", "FORMATS", "DEFAULT_BUDGETS", "DEFAULT_SWITCH_PX", "LIBRARY_TABLES",
           "IMPOSTOR_KINDS", "DEFAULT_IMPOSTOR_TILE", "LEAF_KINDS", "species_of_trees", "WIND_CLIP_DEFAULTS",
           "WIND_CLIP_KEYS"]

FORMATS = ("glb", "usd", "obj", "fbx", "blend", "collision")  # every format, and the default
_MADE_FROM_GLB = ("fbx", "blend")
DEFAULT_BUDGETS = (0.40, 0.12, 0.04)
DEFAULT_SWITCH_PX = (512, 256, 128, 64)  # LOD1, LOD2, LOD3, impostor
# Crossed planes (the portable default any glTF viewer draws) or an octahedral atlas (a shader picks its frames).
IMPOSTOR_KINDS = ("crossed", "octahedral")
DEFAULT_IMPOSTOR_TILE = 128  # px; an octahedral atlas takes the largest tile up to this that fits MAX_ATLAS_PX
# Leaves as alpha-tested cards (the default) or as opaque outline polygons traced from the leaf texture's alpha
# (`species.studio.leaf_cutout`), for engines that draw full geometry faster than alpha tests (Nanite).
LEAF_KINDS = ("cards", "cutout")
_TOP_KEYS = {"name", "seed", "species", "per_species", "lod_budgets", "switch_px", "formats", "texture_size",
             "twig_cards", "impostor", "impostor_frames", "impostor_tile", "shard_size", "resources",
             "leaves"}
# Spec fields the job record leaves out while they hold these values: they came after library.json was first
# written, and leaving them out keeps the default library's records and spec digest as they were.
_OMITTED_WHEN = {"twig_cards": True, "impostor": "crossed", "impostor_frames": OCTAHEDRAL_FRAMES,
                 "leaves": "cards"}
# Baked skeletal wind (species.studio.skeletal_wind): off by default (the one value that decides it), or on
# with the clip's joint budget and wind.
_WIND_CLIP_DEFAULTS = WindClipSettings()
WIND_CLIP_DEFAULTS = {"skeletal_wind": False, "wind_joints": _WIND_CLIP_DEFAULTS.joint_budget,
                      "wind_strength": _WIND_CLIP_DEFAULTS.strength, "wind_gust": _WIND_CLIP_DEFAULTS.gust,
                      "wind_period_s": _WIND_CLIP_DEFAULTS.period_s}
WIND_CLIP_KEYS = tuple(WIND_CLIP_DEFAULTS)
_TOP_KEYS |= set(WIND_CLIP_KEYS)
_OMITTED_WHEN.update(WIND_CLIP_DEFAULTS)
# The library's trees table holds the skeletons (and carries resume); the meshes are the assets' own files, so
# no views and no GLB column.
LIBRARY_TABLES = DatasetTables(view_outputs=(), store_glb=False)
# The job record's `render` says what the views table holds, as a JobSpec's does (dataset readers take its
# outputs from there); its rig and size are the values library records have always carried, kept so that
# library.json, _job.json and the spec digest keep their bytes.
_RECORD_RENDER = {"rig": "tsn4", "size": 64}
# Keys `to_dict` adds to the spec's own fields: `library_spec_from_record` leaves them out.
_RECORD_ONLY_KEYS = ("kind", "render", "store_glb")


class LibrarySpecError(JobSpecError):
    """A library spec has a missing, unknown or impossible field."""

    subject = "library spec"


@contextmanager
def _library_errors():
    """The farm's spec checks raise JobSpecError; in a library spec they read as library spec errors."""
    try:
        yield
    except LibrarySpecError:
        raise
    except JobSpecError as exc:
        raise LibrarySpecError(exc.field, exc.value, exc.allowed) from None


@dataclass(frozen=True)
class LibrarySpec(PipelineSpec):
    """One asset-library job.

    name          : job name (the dataset tables' tree ids are f"{name}-{index:08d}").
    seed          : job seed; asset i grows from `tree_seed(seed, i)`; its id is f"{species}-{seed:016x}".
    species       : preset name -> number of variants, in spec order.
    lod_budgets   : LOD1.. triangle budgets as fractions of LOD0, strictly decreasing, in (0, 1).
    switch_px     : tree height on screen (px, 1080-px reference screen) at which LOD1.., then the impostor,
                    take over; strictly decreasing, one more than lod_budgets.
    formats       : files written per asset (glb, usd, obj, fbx, collision) and per species (blend).
    texture_size  : bark texture height in pixels (leaf atlas tiles are half of it).
    twig_cards    : whether the LOD fit may draw dropped branches as twig (and bark) cluster cards; False keeps
                    every level to tubes and leaf cards: about half the asset's time, at some silhouette fidelity
                    on twiggy crowns (docs/library.md).
    impostor      : "crossed" (8 crossed planes, 16 triangles; the default) or "octahedral" (one quad and a
                    hemi-octahedral atlas of views, `renderers.octahedral_impostor`).
    impostor_frames : octahedral frames per side of the atlas grid (FRAMES_RANGE); crossed: the default, unused.
    impostor_tile : pixels per impostor atlas tile (crossed: one tile per plane, 8 tiles in 4 columns;
                    octahedral: one per frame, impostor_frames x impostor_tile at most MAX_ATLAS_PX).
    skeletal_wind : whether each asset carries baked skeletal wind (joints, skinned bark, leaves under their
                    joints, a looping `wind` clip in the GLB, USD and FBX; docs/library.md, "Skeletal wind").
    wind_joints   : joints at most (JOINT_BUDGET_RANGE; at least the trunk's TRUNK_SEGMENTS).
    wind_strength, wind_gust, wind_period_s : the clip's wind (strength in [0, 1], the share of the lean that
                    comes and goes with the gust in [0, 1], seconds of one loop > 0).
    shard_size    : assets per shard; resources: Ray resources per worker actor.
    leaves        : "cards" (alpha-tested leaf cards; the default) or "cutout" (each single leaf an opaque outline
                    polygon of a few triangles, at every level that keeps single leaves; clump cards stay cards).
    """

    name: str = "library"
    seed: int = 0
    species: dict[str, float] = field(default_factory=dict)
    lod_budgets: tuple[float, ...] = DEFAULT_BUDGETS
    switch_px: tuple[int, ...] = DEFAULT_SWITCH_PX
    formats: tuple[str, ...] = FORMATS
    texture_size: int = 256
    twig_cards: bool = True
    impostor: str = "crossed"
    impostor_frames: int = OCTAHEDRAL_FRAMES
    impostor_tile: int = DEFAULT_IMPOSTOR_TILE
    shard_size: int = 4
    resources: dict[str, float] = field(default_factory=lambda: {"num_cpus": 1.0, "num_gpus": 0.0})
    leaves: str = "cards"
    skeletal_wind: bool = WIND_CLIP_DEFAULTS["skeletal_wind"]
    wind_joints: int = _WIND_CLIP_DEFAULTS.joint_budget
    wind_strength: float = _WIND_CLIP_DEFAULTS.strength
    wind_gust: float = _WIND_CLIP_DEFAULTS.gust
    wind_period_s: float = _WIND_CLIP_DEFAULTS.period_s

    @property
    def wind_clip(self) -> WindClipSettings | None:
        """The skeletal wind clip's settings, None when the assets carry none."""
        if not self.skeletal_wind:
            return None
        return WindClipSettings(strength=self.wind_strength, gust=self.wind_gust, period_s=self.wind_period_s,
                                joint_budget=self.wind_joints)

    @property
    def tables(self) -> DatasetTables:
        """No views and no GLB column (`LIBRARY_TABLES`): what the pipeline writes of a library's trees."""
        return LIBRARY_TABLES

    @property
    def species_counts(self) -> dict[str, int]:
        return {name: int(count) for name, count in self.species.items()}

    def to_dict(self) -> dict:
        out = asdict(self)
        for key in ("lod_budgets", "switch_px", "formats"):
            out[key] = list(out[key])
        out["species"] = {name: int(count) for name, count in self.species.items()}
        out["kind"] = "library"
        out["render"] = {**_RECORD_RENDER, "outputs": list(self.tables.view_outputs)}
        out["store_glb"] = self.tables.store_glb
        for key, value in _OMITTED_WHEN.items():
            if out[key] == value:
                del out[key]
        return out

    def digest(self) -> str:
        """sha256 of everything that decides the files' bytes (not `resources`)."""
        content = self.to_dict()
        content.pop("resources")
        return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def _check_fractions(name: str, value: Any) -> tuple[float, ...]:
    allowed = "a strictly decreasing list of fractions of LOD0 triangles in (0, 1), e.g. [0.4, 0.12, 0.04]"
    if not isinstance(value, (list, tuple)) or not 1 <= len(value) <= 3:
        raise LibrarySpecError(name, value, allowed + " (1 to 3 levels)")
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not 0.0 < item < 1.0:
            raise LibrarySpecError(name, value, allowed)
    if any(b >= a for a, b in zip(value, value[1:])):
        raise LibrarySpecError(name, value, allowed)
    if value[-1] < 0.002:
        raise LibrarySpecError(name, value, allowed + " with the last >= 0.002 (room for a trunk and a card)")
    return tuple(float(v) for v in value)


def parse_library_spec(raw: dict | None, known_species=None) -> LibrarySpec:
    """Validate a library spec mapping; None or {} gives the default (every preset, 4 variants each)."""
    with _library_errors():
        return _parse_library_spec(raw, known_species)


def _parse_library_spec(raw: dict | None, known_species=None) -> LibrarySpec:
    raw = check_keys("", raw or {}, _TOP_KEYS)
    known = list(known_species) if known_species is not None else preset_names()
    name = raw.get("name", "library")
    if not isinstance(name, str) or not name.replace("_", "").replace("-", "").isalnum():
        raise LibrarySpecError("name", name, "letters, digits, '_' and '-'")
    seed = check_seed(raw.get("seed", 0))
    per_species = check_int("per_species", raw.get("per_species", 4), 1, 100_000)
    mix = raw.get("species")
    if mix is None:
        mix = {preset: per_species for preset in known}
    elif isinstance(mix, list):
        mix = {preset: per_species for preset in mix}
    if not isinstance(mix, dict) or not mix:
        raise LibrarySpecError("species", mix, "a list of preset names or a mapping name -> variants")
    species = {}
    for preset, count in mix.items():
        if preset not in known:
            raise LibrarySpecError(f"species.{preset}", preset, f"a known species: {', '.join(sorted(known))}")
        species[preset] = float(check_int(f"species.{preset}", count, 1, 100_000))
    budgets = _check_fractions("lod_budgets", raw.get("lod_budgets", list(DEFAULT_BUDGETS)))
    switch = raw.get("switch_px", list(DEFAULT_SWITCH_PX[:len(budgets)]) + [DEFAULT_SWITCH_PX[-1]])
    allowed = f"a strictly decreasing list of {len(budgets) + 1} pixel heights (LODs then the impostor)"
    if (not isinstance(switch, (list, tuple)) or len(switch) != len(budgets) + 1
            or any(isinstance(v, bool) or not isinstance(v, int) or not 8 <= v <= 4096 for v in switch)
            or any(b >= a for a, b in zip(switch, switch[1:]))):
        raise LibrarySpecError("switch_px", switch, allowed + " in [8, 4096]")
    formats = raw.get("formats", list(FORMATS))
    if not isinstance(formats, (list, tuple)) or not formats:
        raise LibrarySpecError("formats", formats, f"a list from: {', '.join(FORMATS)}")
    for item in formats:
        if item not in FORMATS:
            raise LibrarySpecError("formats", item, f"formats from: {', '.join(FORMATS)}")
    for item in formats:
        # Blender makes the FBX files and the .blend from the asset's GLB: without it there is nothing to import.
        if item in _MADE_FROM_GLB and "glb" not in formats:
            raise LibrarySpecError("formats", list(formats), f"{item!r} together with 'glb' (Blender makes {item} "
                                   f"from the asset's GLB)")
    texture_size = check_int("texture_size", raw.get("texture_size", 256), 32, 4096)
    if texture_size % 4:
        raise LibrarySpecError("texture_size", texture_size, "a multiple of 4 in [32, 4096]")
    twig_cards = raw.get("twig_cards", True)
    if not isinstance(twig_cards, bool):
        raise LibrarySpecError("twig_cards", twig_cards, "true or false")
    impostor = raw.get("impostor", "crossed")
    if impostor not in IMPOSTOR_KINDS:
        raise LibrarySpecError("impostor", impostor, f"one of: {', '.join(IMPOSTOR_KINDS)}")
    frames = check_int("impostor_frames", raw.get("impostor_frames", OCTAHEDRAL_FRAMES), *FRAMES_RANGE)
    if impostor != "octahedral" and "impostor_frames" in raw:
        raise LibrarySpecError("impostor_frames", frames, "only with impostor: octahedral (crossed planes have no "
                               "frames)")
    largest = MAX_ATLAS_PX // frames if impostor == "octahedral" else 2048
    tile = check_int("impostor_tile", raw.get("impostor_tile", min(DEFAULT_IMPOSTOR_TILE, largest)), 16, 2048)
    if tile > largest:
        raise LibrarySpecError("impostor_tile", tile, f"at most {largest} px with impostor_frames {frames}: the "
                               f"octahedral atlas (impostor_frames x impostor_tile px square) is at most "
                               f"{MAX_ATLAS_PX} px")
    shard_size = check_int("shard_size", raw.get("shard_size", 4), 1, 10_000)
    resources = check_resources(raw.get("resources", {}))
    wind = _parse_wind_clip(raw)
    leaves = raw.get("leaves", "cards")
    if leaves not in LEAF_KINDS:
        raise LibrarySpecError("leaves", leaves, f"one of: {', '.join(LEAF_KINDS)}")
    return LibrarySpec(name=name, seed=seed, species=species, lod_budgets=budgets, switch_px=tuple(switch),
                       formats=tuple(dict.fromkeys(formats)), texture_size=texture_size, twig_cards=twig_cards,
                       impostor=impostor,
                       impostor_frames=frames, impostor_tile=tile,
                       shard_size=shard_size, resources=resources, leaves=leaves, **wind)


def _parse_wind_clip(raw: dict) -> dict:
    """The skeletal wind fields of a spec mapping (their defaults where absent); the clip's own fields only with
    `skeletal_wind: true`."""
    on = raw.get("skeletal_wind", WIND_CLIP_DEFAULTS["skeletal_wind"])
    if not isinstance(on, bool):
        raise LibrarySpecError("skeletal_wind", on, "true or false")
    given = [key for key in WIND_CLIP_KEYS[1:] if key in raw]
    if given and not on:
        raise LibrarySpecError(given[0], raw[given[0]], "only with skeletal_wind: true (the clip it sets)")
    low, high = JOINT_BUDGET_RANGE
    joints = raw.get("wind_joints", WIND_CLIP_DEFAULTS["wind_joints"])
    if isinstance(joints, bool) or not isinstance(joints, int) or not low <= joints <= high:
        raise LibrarySpecError("wind_joints", joints, f"an integer in [{low}, {high}] (at least the trunk's "
                               f"{TRUNK_SEGMENTS} segments)")
    out = {"skeletal_wind": on, "wind_joints": joints}
    for key, allowed in (("wind_strength", "a number in [0, 1]"), ("wind_gust", "a number in [0, 1]"),
                         ("wind_period_s", "a number of seconds > 0 (and at most 600)")):
        value = raw.get(key, WIND_CLIP_DEFAULTS[key])
        bad = isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
        top = 600.0 if key == "wind_period_s" else 1.0
        if bad or not (0.0 < value <= top if key == "wind_period_s" else 0.0 <= value <= top):
            raise LibrarySpecError(key, value, allowed)
        out[key] = float(value)
    return out


def load_library_spec(path: str | Path, **known) -> LibrarySpec:
    """Read and validate a YAML library spec file with the farm's spec loader (`farm.jobs.load_spec`)."""
    with _library_errors():
        return load_spec(path, parse=parse_library_spec, **known)


def default_library_spec(per_species: int = 4) -> LibrarySpec:
    return parse_library_spec({"per_species": per_species})


def library_spec_from_record(record: dict, known_species=None) -> LibrarySpec:
    """The LibrarySpec of a `LibrarySpec.to_dict()` mapping (library.json's `spec`), validated again."""
    return parse_library_spec({k: v for k, v in record.items() if k not in _RECORD_ONLY_KEYS}, known_species)
