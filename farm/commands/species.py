"""`farm species`: the species presets of every growth model, with their generator and a one-line description."""
from __future__ import annotations

import argparse

import species

from farm.commands import CommandLineError
from farm.table import format_table


def register(subparsers) -> None:
    parser = subparsers.add_parser("species", help="list species presets", description=__doc__)
    parser.add_argument("--generator", help="only presets of this generator (weber_penn, colonization, lsystem)")
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    if args.generator is not None and args.generator not in species.GENERATORS:
        raise CommandLineError(f"unknown generator {args.generator!r}; known: "
                               f"{', '.join(sorted(species.GENERATORS))}")
    presets = species.list_presets(args.generator)
    print(format_table(["name", "generator", "description"], [(p.name, p.generator, p.description) for p in presets]))
    return 0
