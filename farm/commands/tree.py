"""`farm tree`: grow trees from a species preset or from parameter dictionaries and write GLB or OBJ files.

  farm tree --species NAME --seed N --out FILE.glb
  farm tree --params DICT.json|PRESET.py [...] --out DIR [--format obj] [--verbose]

A --params file is a JSON dictionary or a preset file of Blender's Sapling add-on (`.py`, as it saves them; or the
same as JSON). Its `draws` key says how the variation keys read: `realized` (TreeSketchNet's dictionaries and
treefarm's presets: scaleV, scaleV0, leafScaleV, curveV1/2, splitAngleV1/2, ... are stored draws) or `ranges`
(Sapling's presets: scaleV, scaleV0, leafScaleV, curveV, splitAngleV are ranges drawn from the dictionary's seed as
Sapling draws them). Without it, a dictionary holding curveV, splitAngleV, a Blender-only key or an old Sapling key
reads as `ranges`, any other as `realized`. Sapling presets load as the add-on loads them: values clamped to its
limits, and the keys it does not use ignored (keys it no longer defines or never did, and the stored draws beside
its ranges: the tree grows from the ranges; a JSON preset that says `draws: realized` keeps its stored draws).
Keys that only drive Blender (armature, wind animation, display) are ignored in any dictionary. --verbose lists
the ignored keys and the clamped values. A dictionary with no key that describes a tree (`{}`) is refused.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

import species
from species.errors import ParameterError, TreefarmError, user_path
from species.meshing import write_tree

from farm.commands import CommandLineError, check_flag_int
from farm.table import format_table

# species.weber_penn is imported where a --params file is read: it is the one generator `farm --help` would
# otherwise load (start-up time).

FORMATS = ("glb", "obj")


class ParamsFileError(TreefarmError):
    """A --params file is missing, not JSON, or not a JSON object of parameters."""


def register(subparsers) -> None:
    parser = subparsers.add_parser("tree", help="grow trees and write GLB/OBJ files", description=__doc__,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--species", help="preset name (see `farm species`)")
    source.add_argument("--params", nargs="+", metavar="DICT.json",
                        help="parameter dictionaries (JSON) or Sapling preset files (.py)")
    parser.add_argument("--seed", type=int, default=0, help="seed for sampling the preset (default 0)")
    parser.add_argument("--out", required=True, help="output file (--species) or folder (--params)")
    parser.add_argument("--format", choices=FORMATS, default=None, help="glb (default) or obj")
    parser.add_argument("--save-params", action="store_true", help="also write the sampled dictionary as JSON")
    parser.add_argument("--verbose", action="store_true",
                        help="say how each --params file reads: draws, ignored keys, clamped values")
    parser.set_defaults(run=run)


def grow_tree(params: dict):
    """Grow and mesh one dictionary with the rng its own seed defines; returns (skeleton, mesh, seconds)."""
    start = time.perf_counter()
    skeleton, mesh = species.rebuild(params)
    return skeleton, mesh, time.perf_counter() - start


def load_params(path: str) -> dict:
    """The dictionary of a --params file; a Sapling preset (a .py file, or JSON that reads as `draws: ranges`) is
    read as the add-on loads it (`species.weber_penn.load_sapling_preset`)."""
    return _read_params(path)[0]


def _read_params(path: str):
    """(dictionary, SaplingPreset or None) of a --params file."""
    from species.weber_penn import load_sapling_preset, reads_as_sapling_preset, sapling_preset_from_settings

    file = Path(path)
    if not file.is_file():
        raise ParamsFileError(f"parameter file {path} is missing or not a file: allowed a JSON file of parameters "
                              f"or a Sapling preset (.py)")
    if file.suffix == ".py":
        with user_path(path, "read"), _naming(path, ParameterError):
            preset = load_sapling_preset(file)
        return preset.params, preset
    with user_path(path, "read"):
        data = file.read_bytes()
    try:
        params = json.loads(data)
    except json.JSONDecodeError as exc:
        raise ParamsFileError(f"{path} is not valid JSON: {exc.msg} at line {exc.lineno}") from None
    except UnicodeDecodeError:
        raise ParamsFileError(f"{path} is not valid JSON: allowed UTF-8 text") from None
    if not isinstance(params, dict):
        raise ParamsFileError(f"{path} must hold a JSON object of parameters, not {type(params).__name__}")
    if params.get("generator", "weber_penn") == "weber_penn":
        with _naming(path, TreefarmError):
            if reads_as_sapling_preset(params):  # the file already read: loaded as the add-on loads a preset
                preset = sapling_preset_from_settings(params)
                return preset.params, preset
    return params, None


@contextmanager
def _naming(path: str, errors: type[Exception]):
    """Raise an error of `errors` inside the block as a ParamsFileError whose line starts with the file's name."""
    try:
        yield
    except errors as exc:
        raise ParamsFileError(f"{path}: {str(exc).strip()}") from None


def _species_output(args: argparse.Namespace) -> tuple[Path, str]:
    """The file and format of `--species ... --out FILE`: FILE names a file, and its suffix agrees with --format."""
    if args.out.endswith(("/", os.sep)) or Path(args.out).is_dir():
        raise CommandLineError(f"--out {args.out} is a folder: with --species, --out names the file to write "
                               f"(e.g. {Path(args.out) / args.species}.glb)")
    out = Path(args.out)
    suffix = out.suffix.lstrip(".").lower()
    if args.format is None:
        return out, suffix if suffix in FORMATS else "glb"
    if suffix in FORMATS and suffix != args.format:
        raise CommandLineError(f"--format {args.format} does not match --out {args.out}: allowed a .{args.format} "
                               f"file name, or --format {suffix}")
    return out, args.format


def _params_output(args: argparse.Namespace) -> Path:
    """The folder of `--params ... --out DIR`: a folder, not a file name ending in a mesh format."""
    folder = Path(args.out)
    if folder.suffix.lstrip(".").lower() in FORMATS or folder.is_file():
        raise CommandLineError(f"--out {args.out} names a file: with --params, --out is the folder that gets one "
                               f"file per dictionary")
    return folder


def _grown_dictionaries(paths: list[str], verbose: bool = False) -> list[tuple[str, dict, tuple]]:
    """(file stem, dictionary, (skeleton, mesh, seconds)) of every --params file, all read and grown before any
    is written; an error names its file, and two files of the same stem (one output name) are refused.
    verbose : print how each file reads (draws, ignored keys, clamped values)."""
    stems: dict[str, str] = {}
    for path in paths:
        stem = Path(path).stem
        if stem in stems:
            raise CommandLineError(f"--params {stems[stem]} and {path} would both write {stem}: allowed files "
                                   f"of different names")
        stems[stem] = path
    loaded = [(Path(p).stem, p, *_read_params(p)) for p in paths]
    if verbose:
        for _, path, params, preset in loaded:
            print(_reading(path, params, preset))
    grown = []
    for stem, path, params, _ in loaded:
        try:
            grown.append((stem, params, grow_tree(params)))
        except TreefarmError as exc:
            raise ParamsFileError(f"{path}: {str(exc).strip()}") from exc
    return grown


def _reading(path: str, params: dict, preset) -> str:
    """How a --params file reads, for --verbose: its draws, the keys it holds that are ignored (and why), and a
    Sapling preset's clamped values."""
    from species.weber_penn import draws_reading, ignored_keys

    generator = params.get("generator", "weber_penn")
    if generator != "weber_penn":
        return f"{path}: generator {generator}"
    lines = [f"{path}: Weber-Penn, draws: {draws_reading(params)}"]
    ignored = ignored_keys(params) if preset is None else preset.ignored
    lines += [f"  ignored {key}: {why}" for key, why in sorted(ignored.items())]
    if preset is not None:
        lines += [f"  clamped {key}: {before} -> {after} (Sapling's limits)"
                  for key, (before, after) in sorted(preset.clamped.items())]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    check_flag_int("--seed", args.seed, 0)
    rows = []
    if args.species:
        out, fmt = _species_output(args)
        params = species.sample(args.species, np.random.default_rng(args.seed))
        skeleton, mesh, seconds = grow_tree(params)
        mesh = _named(mesh, out.stem)
        files = write_tree(mesh, out, fmt)
        if args.save_params:
            with user_path(out.with_suffix(".json"), "write"):
                out.with_suffix(".json").write_text(json.dumps(params, indent=1, sort_keys=True))
        rows.append(_row(out.stem, params, skeleton, mesh, seconds, files[0]))
    else:
        folder = _params_output(args)
        fmt = args.format or "glb"
        for stem, params, (skeleton, mesh, seconds) in _grown_dictionaries(args.params, args.verbose):
            mesh = _named(mesh, stem)
            files = write_tree(mesh, folder / f"{stem}.{fmt}", fmt)
            rows.append(_row(stem, params, skeleton, mesh, seconds, files[0]))
    print(format_table(["tree", "species", "height_m", "crown_radius_m", "vertices", "faces", "seconds", "file"], rows))
    return 0


def _named(mesh, name: str):
    from dataclasses import replace

    return replace(mesh, name=name)


def _row(name, params, skeleton, mesh, seconds, file):
    return (name, params.get("species", params.get("generator", "weber_penn")), round(skeleton.height, 2),
            round(skeleton.crown_radius, 2), mesh.n_vertices, mesh.n_faces, round(seconds, 3), str(file))
