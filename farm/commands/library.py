"""`farm library`: build a studio asset library (LODs, impostor, wind, seasons; GLB, USD, OBJ, FBX) on the farm.

`farm library [SPEC.yaml] --out DIR [--species NAME[,NAME]] [--per-species N]` (no spec: every preset, 4 variants
each; resumable), `farm library validate DIR [--quality]` (--quality: each level's IoU beside its
half-pixel floor), `farm library add DIR --species NAME --seed N`.
"""
from __future__ import annotations

import argparse

from farm.commands import CommandLineError
from farm.commands.ray_options import add_ray_options, check_workers
from farm.table import format_table

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("library", help="build a studio asset library of trees (resumable)",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("spec", nargs="?", help="library spec YAML, or `validate` / `add` (see below)")
    parser.add_argument("folder", nargs="?", help="the library folder (for validate and add)")
    parser.add_argument("--out", help="output folder of a library job")
    parser.add_argument("--per-species", type=int, help="variants per species (overrides the spec)")
    add_ray_options(parser, workers_help="worker actors (default: one per CPU)")
    parser.add_argument("--species", help="(add) the species preset of the new asset; (build) the species to "
                        "build, NAME[,NAME], from the spec's (default: all)")
    parser.add_argument("--seed", type=int, help="(add) the tree seed of the new asset")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument("--quality", action="store_true",
                        help="(validate) rebuild each asset's LOD0 and report every level's IoU beside its "
                             "half-pixel floor (the restated target: IoU >= floor - 0.02)")
    parser.set_defaults(run=run)


def _load(args):
    from farm.library.spec import LibrarySpecError, library_spec_from_record, load_library_spec, parse_library_spec

    if args.spec:
        spec = load_library_spec(args.spec)
    else:
        spec = parse_library_spec({})
    counts = spec.species_counts
    if args.species is not None:
        chosen = [name.strip() for name in args.species.split(",")]
        for name in chosen:
            if name not in counts:
                raise LibrarySpecError("--species", name, f"species of the spec, comma-separated: "
                                       f"{', '.join(counts)}")
        counts = {name: counts[name] for name in dict.fromkeys(chosen)}
    if args.per_species is not None:
        if args.per_species < 1:
            raise LibrarySpecError("--per-species", args.per_species, "an integer >= 1")
        counts = {name: args.per_species for name in counts}
    if counts != spec.species_counts:
        spec = library_spec_from_record({**spec.to_dict(), "species": counts})
    return spec


def _print_floors(folder: str, progress: bool) -> None:
    from farm.library.catalog import refresh_catalog_tables
    from farm.library.quality import FLOOR_MARGIN, library_floors, store_floors
    from farm.dataset.storage import Location

    floors = library_floors(folder, progress=progress)
    store_floors(Location.resolve(folder), floors)
    refresh_catalog_tables(folder)  # the catalog's iou_floor column now holds them
    rows = [[f.asset, f.level, f.switch_px, f"{f.iou:.3f}", f"{f.floor:.3f}", f"{f.margin:+.3f}",
             "meets" if f.meets else "misses"] for f in floors]
    print(format_table(["asset", "level", "switch px", "least IoU", "half-pixel floor", "margin",
                        f"IoU >= floor - {FLOOR_MARGIN}"], rows))


def _validate(args: argparse.Namespace) -> int:
    """`farm library validate DIR [--quality]`: the files against their records, then the levels against their
    half-pixel floors (a level below its floor is reported, not damage: the files are what the spec asked for)."""
    from farm.commands.validate import report_damage
    from farm.library.catalog import validate_library
    from farm.library.quality import catalog_quality

    if not args.folder:
        raise CommandLineError("farm library validate needs the library folder: farm library validate DIR")
    problems = validate_library(args.folder)
    if problems:
        return report_damage(args.folder, problems, "`farm library` with the same spec retries failed FBX exports "
                             "in this folder, and builds every file again (the same bytes) into a new --out")
    if args.quality:
        _print_floors(args.folder, progress=not args.quiet)
    quality = catalog_quality(args.folder)
    print(f"{args.folder}: ok, the files of its {quality.assets} assets match their asset.json; "
          f"{quality.summary()}")
    return 0


def run(args: argparse.Namespace) -> int:
    if args.quality and args.spec != "validate":
        raise CommandLineError("--quality is a `farm library validate DIR` option")
    if args.spec == "validate":
        return _validate(args)
    if args.spec == "add":
        from farm.library.job import add_asset

        if not args.folder or args.species is None or args.seed is None:
            raise CommandLineError("usage: farm library add DIR --species NAME --seed N")
        record = add_asset(args.folder, args.species, args.seed)
        print(f"{args.folder}: added {record['id']}")
        return 0
    if args.seed is not None:
        # A build's seeds come from the spec's `seed`; a --seed meant for `add` must not start another job.
        raise CommandLineError("--seed is for `farm library add DIR --species NAME --seed N`; a library build "
                               "takes its seed from the spec's `seed` field")
    spec = _load(args)
    if not args.out:
        raise CommandLineError("no output location: pass --out DIR")
    check_workers(args.workers)
    from farm.library.job import run_library

    result = run_library(spec, args.out, workers=args.workers, address=args.address, progress=not args.quiet)
    counts = result["manifest"]["counts"]
    print(f"{args.out}: {result['catalog']['assets']} assets ({counts['failed']} failed); "
          f"blender outputs: {result['catalog']['blender']}")
    return 0
