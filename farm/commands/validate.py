"""`farm validate DIR`: check a dataset's part files against the manifest (presence, size, sha256, schema, rows).

Prints each damaged file with what is wrong and exits 1; prints a one-line summary and exits 0 when all is well;
a folder with no manifest is not a dataset: one line, exit 2.
"""
from __future__ import annotations

import argparse
import sys

from farm.table import counted

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("validate", help="check schema and checksums; name any damaged file",
                                   description=__doc__)
    parser.add_argument("dir", help="dataset folder or URI")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from farm.dataset import read_manifest
    from farm.dataset.manifest import validate_dataset
    from farm.dataset.storage import Location

    location = Location.resolve(args.dir)
    if not location.exists("manifest.json"):  # not a dataset at all (status 2), rather than a damaged one (1)
        read_manifest(location)
    problems = validate_dataset(args.dir)
    for problem in problems:
        print(f"damaged: {problem}", file=sys.stderr)
    if problems:
        print(f"{args.dir}: {counted(len(problems), 'damaged file')}; `farm generate` with the same spec "
              f"regenerates them", file=sys.stderr)
        return 1
    manifest = read_manifest(args.dir)
    counts = manifest["counts"]
    print(f"{args.dir}: ok, {counted(2 * len(manifest['shards']), 'part file')} match the manifest "
          f"({counted(counts['trees'], 'tree')}, {counted(counts['views'], 'view')})")
    return 0
