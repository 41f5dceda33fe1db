"""`farm generate`: run (or resume) a generation job from a YAML spec or the built-in default.

`farm generate --print-spec` prints the default spec as YAML, a starting point for your own.
"""
from __future__ import annotations

import argparse
import sys
import time

from farm.commands import CommandLineError
from farm.commands.ray_options import add_ray_options, check_workers
from farm.table import counted

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("generate", help="grow, render and write a dataset of trees (resumable)",
                                   description=__doc__)
    parser.add_argument("spec", nargs="?", help="job spec YAML (default: the built-in job)")
    parser.add_argument("--out", help="output folder or URI (s3://, gs://); default: the spec's `output`")
    parser.add_argument("--trees", type=int, help="total number of trees, split over the spec's species")
    add_ray_options(parser, workers_help="worker actors (default: one per CPU)")
    parser.add_argument("--print-spec", action="store_true", help="print the (default) spec as YAML and exit")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(run=run)


def load_job(args: argparse.Namespace):
    from farm.jobs import default_spec, load_spec

    spec = load_spec(args.spec) if args.spec else default_spec()
    if args.trees is not None:
        spec = spec.with_trees(args.trees)
    return spec


def run(args: argparse.Namespace) -> int:
    from farm.jobs import spec_to_yaml

    spec = load_job(args)
    if args.print_spec:
        sys.stdout.write(spec_to_yaml(spec))
        return 0
    out = args.out or spec.output
    if not out:
        raise CommandLineError("no output location: pass --out DIR (or set `output` in the spec)")
    check_workers(args.workers)
    from farm.pipeline import run_job

    def say_resuming(kept: int, total: int) -> None:
        print(f"{out}: resuming: {kept} of {counted(total, 'tree')} kept", flush=True)  # before the bar starts

    # This command's own clock: the manifest's wall time is that of the run that finished the job.
    start = time.perf_counter()
    manifest = run_job(spec, out, workers=args.workers, address=args.address, progress=not args.quiet,
                       on_resume=say_resuming)
    seconds = time.perf_counter() - start
    counts = manifest["counts"]
    print(f"{out}: {counted(counts['trees'], 'tree')} ({counts['failed']} failed), "
          f"{counted(counts['views'], 'view')} in {counted(counts['shards'], 'shard')}; {seconds:.1f} s this run")
    return 0
