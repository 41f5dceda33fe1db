"""`farm validate DIR`: check a dataset's part files against the manifest (presence, size, sha256, schema, rows).

Every `validate` (this one and `farm library validate`) answers the same way (docs/cli.md): damage found is a
`damaged: PATH: what` line per file and a summary on stderr, exit 1 (`report_damage`); all well is one
`DIR: ok, ...` line, exit 0; a folder that is not what the command checks is bad input: `farm: error:`, exit 2.
"""
from __future__ import annotations

import argparse
import sys
from typing import Sequence

from farm.table import counted

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("validate", help="check schema and checksums; name any damaged file",
                                   description=__doc__)
    parser.add_argument("dir", help="dataset folder or URI")
    parser.set_defaults(run=run)


def report_damage(folder: str, problems: Sequence[object], remedy: str) -> int:
    """Print what a `validate` found damaged (one `damaged:` line per problem, then a summary saying how to
    repair it) on stderr; returns the exit status, 1."""
    for problem in problems:
        print(f"damaged: {problem}", file=sys.stderr)
    print(f"{folder}: {counted(len(problems), 'damaged file')}; {remedy}", file=sys.stderr)
    return 1


def run(args: argparse.Namespace) -> int:
    from farm.dataset import read_manifest
    from farm.dataset.manifest import validate_dataset
    from farm.dataset.storage import Location

    location = Location.resolve(args.dir)
    if not location.exists("manifest.json"):  # not a dataset at all (status 2), rather than a damaged one (1)
        read_manifest(location)
    problems = validate_dataset(args.dir)
    if problems:
        return report_damage(args.dir, problems, "`farm generate` with the same spec regenerates them")
    manifest = read_manifest(args.dir)
    counts = manifest["counts"]
    print(f"{args.dir}: ok, {counted(2 * len(manifest['shards']), 'part file')} match the manifest "
          f"({counted(counts['trees'], 'tree')}, {counted(counts['views'], 'view')})")
    return 0
