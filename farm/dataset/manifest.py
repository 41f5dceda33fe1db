"""Shard records and the manifest: what a finished shard is, what a finished dataset is, and how to check one.

A worker writes a shard's two part files, then `_shards/part-NNNNN.json` (checksums, row counts, failures,
timings). The driver writes manifest.json last, from those records. Validation re-reads every part file.
"""
from __future__ import annotations

import functools
import json
import platform
import subprocess
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from .readers import read_manifest
from .schema import (DATASET_FORMAT, SCHEMA_VERSION, TABLES, DatasetError, float_outputs_of, part_name,
                     trees_schema, views_schema)
from .storage import Location, sha256_hex

__all__ = ["SHARDS_FOLDER", "JOB_RECORD", "write_job_record", "shard_record_name", "write_shard_record", "read_shard_record", "finished_shards", "build_manifest",
           "write_manifest", "validate_dataset", "Problem", "code_version", "package_versions"]

SHARDS_FOLDER = "_shards"
# Written when a job starts, so `farm status` can report on a job that has no manifest yet.
JOB_RECORD = "_job.json"


def shard_record_name(shard: int) -> str:
    return f"{SHARDS_FOLDER}/part-{shard:05d}.json"


def file_entry(table: str, shard: int, data: bytes, rows: int) -> dict:
    return {"path": part_name(table, shard), "rows": rows, "bytes": len(data), "sha256": sha256_hex(data)}


def write_job_record(location: Location, spec) -> None:
    record = {"job": spec.to_dict(), "spec_digest": spec.digest(), "n_trees": spec.n_trees, "n_shards": spec.n_shards}
    location.write_atomic(JOB_RECORD, json.dumps(record, indent=1).encode())


def write_shard_record(location: Location, record: dict) -> None:
    location.write_atomic(shard_record_name(record["shard"]), json.dumps(record, indent=1).encode())


def read_shard_record(location: Location, shard: int) -> dict | None:
    name = shard_record_name(shard)
    if not location.exists(name):
        return None
    try:
        return json.loads(location.read_bytes(name))
    except json.JSONDecodeError:
        return None  # a damaged record means an unfinished shard: it is regenerated


def _part_intact(location: Location, entry: dict) -> bool:
    if not location.exists(entry["path"]):
        return False
    return sha256_hex(location.read_bytes(entry["path"])) == entry["sha256"]


def finished_shards(location: Location, spec_digest: str, n_shards: int) -> dict[int, dict]:
    """Shards whose record matches this job and whose part files match their checksums, by shard number."""
    done = {}
    for shard in range(n_shards):
        record = read_shard_record(location, shard)
        if record is None or record.get("spec_digest") != spec_digest:
            continue
        if all(_part_intact(location, record[table]) for table in TABLES):
            done[shard] = record
    return done


@functools.cache
def code_version() -> str:
    """`git describe` of the source tree when it is a checkout, else the package version (once per process)."""
    root = Path(__file__).resolve().parent.parent
    try:
        out = subprocess.run(["git", "describe", "--always", "--dirty"], cwd=root, capture_output=True,
                             text=True, timeout=10)
        if out.returncode == 0 and out.stdout.strip():
            return out.stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        pass  # not a git checkout: the installed version below identifies the code
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("treefarm")
    except PackageNotFoundError:
        return "unknown"


def package_versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    versions = {"python": platform.python_version()}
    for name in ("numpy", "scipy", "trimesh", "pyarrow", "ray", "pyrender", "opencv-contrib-python-headless"):
        try:
            versions[name] = version(name)
        except PackageNotFoundError:
            versions[name] = "absent"
    return versions


def build_manifest(spec, records: dict[int, dict], wall_seconds: float) -> dict:
    """The manifest of a finished job from its shard records (in shard order)."""
    shards = [records[k] for k in sorted(records)]
    stage_seconds: dict[str, float] = {}
    for record in shards:
        for stage, seconds in record["timings"]["stages"].items():
            stage_seconds[stage] = stage_seconds.get(stage, 0.0) + seconds
    n_trees = sum(r["trees"]["rows"] for r in shards)
    n_views = sum(r["views"]["rows"] for r in shards)
    return {
        "format": DATASET_FORMAT,
        "schema_version": SCHEMA_VERSION,
        "job": spec.to_dict(),
        "spec_digest": spec.digest(),
        "code_version": code_version(),
        # A resumed job whose shards were written by different code: same spec, maybe not the same bytes.
        "shard_code_versions": sorted({r.get("code_version", "unknown") for r in shards}),
        "packages": package_versions(),
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "counts": {"trees": n_trees, "views": n_views, "failed": sum(len(r["failures"]) for r in shards),
                   "shards": len(shards)},
        "shards": [{key: r[key] for key in ("shard", "first_index", "n_trees", "trees", "views")} for r in shards],
        "failures": [failure for r in shards for failure in r["failures"]],
        # Summed over shards: CPU well below wall means the workers waited for a CPU (an oversubscribed machine).
        "timings": {"wall_seconds": wall_seconds, "stage_seconds": stage_seconds,
                    "shard_wall_seconds": sum(r["timings"].get("wall_seconds", 0.0) for r in shards),
                    "shard_cpu_seconds": sum(r["timings"].get("cpu_seconds", 0.0) for r in shards),
                    "trees_per_second": n_trees / wall_seconds if wall_seconds > 0 else None},
    }


def write_manifest(location: Location, manifest: dict) -> None:
    location.write_atomic("manifest.json", json.dumps(manifest, indent=1).encode())


@dataclass(frozen=True)
class Problem:
    """One damaged or missing file of a dataset."""

    path: str
    reason: str

    def __str__(self) -> str:
        return f"{self.path}: {self.reason}"


def validate_dataset(path: str) -> list[Problem]:
    """Every problem with a finished dataset: missing files, checksum or size mismatch, schema, row counts."""
    import pyarrow.parquet as pq

    location = Location.resolve(path)
    try:
        manifest = read_manifest(location)
    except DatasetError as exc:
        return [Problem(location.path("manifest.json"), str(exc))]
    if manifest.get("schema_version") != SCHEMA_VERSION:
        return [Problem(location.path("manifest.json"),
                        f"schema_version {manifest.get('schema_version')!r}; this code reads {SCHEMA_VERSION}")]
    outputs = manifest["job"]["render"]["outputs"]
    # The float maps are those the first readable views part stores with scale and offset; every part must agree.
    schemas = {"trees": trees_schema(), "views": None}
    problems = []
    for shard in manifest["shards"]:
        for table in TABLES:
            entry = shard[table]
            full = location.path(entry["path"])
            if not location.exists(entry["path"]):
                problems.append(Problem(full, "missing"))
                continue
            data = location.read_bytes(entry["path"])
            if len(data) != entry["bytes"]:
                problems.append(Problem(full, f"{len(data)} bytes; the manifest says {entry['bytes']} (truncated?)"))
                continue
            if sha256_hex(data) != entry["sha256"]:
                problems.append(Problem(full, "sha256 differs from the manifest (corrupted)"))
                continue
            import pyarrow

            # The bytes match the worker's checksum, so the footer is enough; decoding the pages would start
            # Arrow's thread pools, whose threads can still be alive when the interpreter exits (std::terminate).
            try:
                with pq.ParquetFile(pyarrow.BufferReader(data)) as part:
                    schema, rows = part.schema_arrow, part.metadata.num_rows
            except (pyarrow.ArrowException, OSError) as exc:
                problems.append(Problem(full, f"unreadable Parquet: {exc}"))
                continue
            if schemas[table] is None:
                schemas[table] = views_schema(outputs, float_outputs_of(schema.names))
            if not schema.equals(schemas[table], check_metadata=False):
                problems.append(Problem(full, f"schema differs from the {table} schema"))
            elif rows != entry["rows"]:
                problems.append(Problem(full, f"{rows} rows; the manifest says {entry['rows']}"))
    return problems
