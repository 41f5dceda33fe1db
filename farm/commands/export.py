"""`farm export DIR --format glb|obj --to FOLDER`: write each tree of a dataset as a mesh file.

GLB comes from the stored bytes when the job kept them; OBJ (and GLB otherwise) is rebuilt from the tree's
parameter dictionary, which reproduces the tree exactly.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import species
from species.errors import user_path

from farm.commands import CommandLineError

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("export", help="write the trees of a dataset as GLB or OBJ files",
                                   description=__doc__)
    parser.add_argument("dir", help="dataset folder or URI")
    parser.add_argument("--format", required=True, help="glb or obj")
    parser.add_argument("--to", required=True, help="folder to write into (created)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def _rebuild(params_json: str, name: str):
    return species.rebuild(json.loads(params_json), name=name)[1]


def _write_glb(row: dict, folder: Path) -> None:
    data = row["glb"] if row["glb"] is not None else _rebuild(row["params_json"], row["tree_id"]).to_glb()
    with user_path(folder, "write into"):
        (folder / f"{row['tree_id']}.glb").write_bytes(data)


def _write_obj(row: dict, folder: Path) -> None:
    files = _rebuild(row["params_json"], row["tree_id"]).to_obj()
    tree_folder = folder / row["tree_id"]
    with user_path(folder, "write into"):
        tree_folder.mkdir(parents=True, exist_ok=True)
        for file_name, data in files.items():
            (tree_folder / file_name).write_bytes(data)


EXPORTERS = {"glb": _write_glb, "obj": _write_obj}


def run(args: argparse.Namespace) -> int:
    import pyarrow as pa
    import pyarrow.compute as pc
    from tqdm import tqdm

    from farm.dataset import open as open_table

    if args.format not in EXPORTERS:
        raise CommandLineError(f"--format {args.format!r} is unknown: allowed {', '.join(EXPORTERS)}")
    columns = ["tree_id", "params_json", "error"] + (["glb"] if args.format == "glb" else [])
    table = open_table(args.dir, "trees").to_table(columns=columns)
    table = table.filter(pc.is_null(table["error"]))
    if args.format != "glb":
        table = table.append_column("glb", pa.nulls(table.num_rows, pa.binary()))
    folder = Path(args.to)
    with user_path(folder, "make the folder"):
        folder.mkdir(parents=True, exist_ok=True)
    for row in tqdm(table.to_pylist(), unit="tree", desc=f"export {args.format}", disable=args.quiet):
        EXPORTERS[args.format](row, folder)
    print(f"wrote {table.num_rows} trees as {args.format} to {folder}")
    return 0
