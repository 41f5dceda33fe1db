"""`farm tree`: grow trees from a species preset or from parameter dictionaries and write GLB or OBJ files.

  farm tree --species NAME --seed N --out FILE.glb
  farm tree --params DICT.json [DICT.json ...] --out DIR [--format obj]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from species.errors import TreefarmError, user_path

FORMATS = ("glb", "obj")


class ParamsFileError(TreefarmError):
    """A --params file is missing, not JSON, or not a JSON object of parameters."""


def register(subparsers) -> None:
    parser = subparsers.add_parser("tree", help="grow trees and write GLB/OBJ files", description=__doc__,
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--species", help="preset name (see `farm species`)")
    source.add_argument("--params", nargs="+", metavar="DICT.json", help="parameter dictionaries (JSON)")
    parser.add_argument("--seed", type=int, default=0, help="seed for sampling the preset (default 0)")
    parser.add_argument("--out", required=True, help="output file (--species) or folder (--params)")
    parser.add_argument("--format", choices=FORMATS, default=None, help="glb (default) or obj")
    parser.add_argument("--save-params", action="store_true", help="also write the sampled dictionary as JSON")
    parser.set_defaults(run=run)


def grow_tree(params: dict):
    """Grow and mesh one dictionary with the rng its own seed defines; returns (skeleton, mesh, seconds)."""
    import species

    start = time.perf_counter()
    skeleton, mesh = species.rebuild(params)
    return skeleton, mesh, time.perf_counter() - start


def write_tree(mesh, path: Path, fmt: str) -> list[Path]:
    """Write one tree as `path` (GLB) or as OBJ + MTL + textures beside it; returns the files written."""
    files = {path.name: mesh.to_glb()} if fmt == "glb" else mesh.to_obj()
    with user_path(path, "write"):
        path.parent.mkdir(parents=True, exist_ok=True)
        for name, data in files.items():
            (path.parent / name).write_bytes(data)
    return [path.parent / name for name in files]


def load_params(path: str) -> dict:
    file = Path(path)
    if not file.is_file():
        raise ParamsFileError(f"parameter file {path} is missing or not a file: allowed a JSON file of parameters")
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
    return params


def run(args: argparse.Namespace) -> int:
    import numpy as np
    import species
    from farm.table import format_table

    rows = []
    if args.species:
        out = Path(args.out)
        fmt = args.format or (out.suffix.lstrip(".").lower() if out.suffix.lower() in (".glb", ".obj") else "glb")
        params = species.sample(args.species, np.random.default_rng(args.seed))
        skeleton, mesh, seconds = grow_tree(params)
        mesh = _named(mesh, out.stem)
        files = write_tree(mesh, out, fmt)
        if args.save_params:
            out.with_suffix(".json").write_text(json.dumps(params, indent=1, sort_keys=True))
        rows.append(_row(out.stem, params, skeleton, mesh, seconds, files[0]))
    else:
        folder = Path(args.out)
        fmt = args.format or "glb"
        loaded = [(Path(p).stem, load_params(p)) for p in args.params]  # read all first: fail before writing
        for stem, params in loaded:
            skeleton, mesh, seconds = grow_tree(params)
            mesh = _named(mesh, stem)
            files = write_tree(mesh, folder / f"{stem}.{fmt}", fmt)
            rows.append(_row(stem, params, skeleton, mesh, seconds, files[0]))
    print(format_table(["tree", "species", "height_m", "crown_m", "vertices", "faces", "seconds", "file"], rows))
    return 0


def _named(mesh, name: str):
    from dataclasses import replace

    return replace(mesh, name=name)


def _row(name, params, skeleton, mesh, seconds, file):
    return (name, params.get("species", params.get("generator", "weber_penn")), round(skeleton.height, 2),
            round(skeleton.crown_radius, 2), mesh.n_vertices, mesh.n_faces, round(seconds, 3), str(file))
