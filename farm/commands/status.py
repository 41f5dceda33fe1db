"""`farm status DIR`: a dataset's counts, failures and per-stage timings (also for an unfinished job).

Reads manifest.json, or the shard records of a job still running or interrupted.
"""
from __future__ import annotations

import argparse
import json

from farm.table import counted

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).


def register(subparsers) -> None:
    parser = subparsers.add_parser("status", help="counts, failures and timings of a dataset", description=__doc__)
    parser.add_argument("dir", help="dataset folder or URI")
    parser.set_defaults(run=run)


def _print_stages(stage_seconds: dict, n_trees: int) -> None:
    total = sum(stage_seconds.values()) or 1.0
    print(f"{'stage':<10}{'seconds':>10}{'share':>8}{'ms/tree':>10}")
    for stage, seconds in stage_seconds.items():
        print(f"{stage:<10}{seconds:>10.2f}{seconds / total:>8.0%}{1000 * seconds / max(n_trees, 1):>10.1f}")


def run(args: argparse.Namespace) -> int:
    from farm.dataset import DatasetError, read_manifest
    from farm.dataset.manifest import SHARDS_FOLDER, JOB_RECORD, read_shard_record
    from farm.dataset.storage import Location

    location = Location.resolve(args.dir)
    if location.exists("manifest.json"):
        manifest = read_manifest(location)
        counts = manifest["counts"]
        print(f"{location.uri}: finished job {manifest['job']['name']!r} (code {manifest['code_version']})")
        print(f"trees {counts['trees']}  views {counts['views']}  shards {counts['shards']}  "
              f"failed {counts['failed']}")
        print(f"wall {manifest['timings']['wall_seconds']:.1f} s (last run)")
        if len(manifest.get("shard_code_versions", [])) > 1:
            print(f"warning: shards written by different code versions: {', '.join(manifest['shard_code_versions'])}")
        _print_stages(manifest["timings"]["stage_seconds"], counts["trees"])
        failures = manifest["failures"]
    else:
        if not location.exists(JOB_RECORD):
            raise DatasetError(f"{location.uri} holds no treefarm job (no manifest.json, no {JOB_RECORD})")
        job = json.loads(location.read_bytes(JOB_RECORD))
        names = [n for n in location.list(SHARDS_FOLDER) if n.startswith("part-")]
        records = [r for r in (read_shard_record(location, int(n[5:10])) for n in names) if r is not None]
        done = sum(r["n_trees"] for r in records)
        print(f"{location.uri}: unfinished job {job['job']['name']!r}: {len(records)} of "
              f"{counted(job['n_shards'], 'shard')}, {done} of {counted(job['n_trees'], 'tree')} written "
              f"(re-run `farm generate` to resume)")
        stages: dict[str, float] = {}
        for record in records:
            for stage, seconds in record["timings"]["stages"].items():
                stages[stage] = stages.get(stage, 0.0) + seconds
        _print_stages(stages, done)
        failures = [f for r in records for f in r["failures"]]
    for failure in failures:
        print(f"failed {failure['tree_id']} ({failure['species']}, seed {failure['seed']}) in "
              f"{failure['stage']}: {failure['error']}")
    return 0
