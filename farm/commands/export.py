"""`farm export DIR --out FOLDER [--format glb|obj]`: write each tree of a dataset as a mesh file.

Files are named SPECIES-TREE_ID (`maple-default-00000003.glb`; OBJ: a folder of that name per tree). GLB (the
default) comes from the stored bytes when the job kept them; OBJ (and GLB otherwise) is rebuilt from the tree's
parameter dictionary, which reproduces the tree exactly. Trees that failed to generate are not exported. `--to` is
the old name of `--out`, still read (deprecated).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import species
from species.errors import user_path

from farm.commands import CommandLineError

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).

DEFAULT_FORMAT = "glb"


def register(subparsers) -> None:
    parser = subparsers.add_parser("export", help="write the trees of a dataset as GLB or OBJ files",
                                   description=__doc__)
    parser.add_argument("dir", help="dataset folder or URI")
    parser.add_argument("--out", help="folder to write into (created)")
    parser.add_argument("--format", default=DEFAULT_FORMAT, help=f"glb or obj (default {DEFAULT_FORMAT})")
    parser.add_argument("--to", help="deprecated: the old name of --out")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def _rebuild(params_json: str, name: str):
    return species.rebuild(json.loads(params_json), name=name)[1]


def export_name(row: dict) -> str:
    """The file (GLB) or folder (OBJ) name of a tree: its species, then its id."""
    return f"{row['species']}-{row['tree_id']}"


def _write_glb(row: dict, folder: Path) -> int:
    data = row["glb"] if row["glb"] is not None else _rebuild(row["params_json"], row["tree_id"]).to_glb()
    with user_path(folder, "write into"):
        (folder / f"{export_name(row)}.glb").write_bytes(data)
    return len(data)


def _write_obj(row: dict, folder: Path) -> int:
    files = _rebuild(row["params_json"], row["tree_id"]).to_obj()
    tree_folder = folder / export_name(row)
    with user_path(folder, "write into"):
        tree_folder.mkdir(parents=True, exist_ok=True)
        for file_name, data in files.items():
            (tree_folder / file_name).write_bytes(data)
    return sum(len(data) for data in files.values())


EXPORTERS = {"glb": _write_glb, "obj": _write_obj}  # each writes one tree and returns the bytes written


def _out_folder(args: argparse.Namespace) -> Path:
    if args.to is not None:
        if args.out is not None and args.out != args.to:
            raise CommandLineError(f"--to {args.to} and --out {args.out}: --to is the deprecated name of --out; "
                                   "allowed one of them")
        print("warning: --to is deprecated: use --out", file=sys.stderr)
        return Path(args.to)
    if args.out is None:
        raise CommandLineError("--out FOLDER is required (the folder to write the trees into)")
    return Path(args.out)


def run(args: argparse.Namespace) -> int:
    import pyarrow as pa
    import pyarrow.compute as pc
    from tqdm import tqdm

    from farm.dataset import open as open_table

    if args.format not in EXPORTERS:
        raise CommandLineError(f"--format {args.format!r} is unknown: allowed {', '.join(EXPORTERS)}")
    folder = _out_folder(args)
    columns = ["tree_id", "species", "params_json", "error"] + (["glb"] if args.format == "glb" else [])
    every_tree = open_table(args.dir, "trees").to_table(columns=columns)
    table = every_tree.filter(pc.is_null(every_tree["error"]))
    failed = every_tree.num_rows - table.num_rows
    if args.format != "glb":
        table = table.append_column("glb", pa.nulls(table.num_rows, pa.binary()))
    with user_path(folder, "make the folder"):
        folder.mkdir(parents=True, exist_ok=True)
    written = 0
    for row in tqdm(table.to_pylist(), unit="tree", desc=f"export {args.format}", disable=args.quiet):
        written += EXPORTERS[args.format](row, folder)
    print(f"{folder}: {table.num_rows} trees as {args.format} ({failed} failed to generate, not exported), "
          f"{written / 1e6:.1f} MB")
    return 0
