"""Blender job runner: `.venv-blender/bin/python worker.py JOB.json [JOB.json ...]`, one scene per job.

Each job file is a JSON object with `kind` (a key of JOBS), `out_dir` and the kind's own keys; the runner
writes `out_dir/result.json` ({"kind", "ok", "seconds", "result"} or {"kind", "ok": false, "error"}).
Exit status: 0 all jobs done, 2 a job was invalid (JobError), 1 Blender or the worker failed.
Self-contained: imports bpy and numpy<2 from this environment, never the treefarm packages.
"""
from __future__ import annotations

import importlib
import json
import os
import sys
import time
import traceback

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from scene import JobError  # noqa: E402  (needs the path above)

# kind -> "module:function" in this folder; function(job: dict, out_dir: str) -> JSON-able dict.
# A new kind (fbx, blend_library, ...) is one module and one line here.
JOBS = {
    "info": "info:run",
    "photos": "photos:run",
    "fbx": "fbx:run", "fbx_info": "fbx:info",
    "asset_library": "asset_library:run", "blend_info": "asset_library:info",
}


def _handler(kind):
    if kind not in JOBS:
        raise JobError(f"job kind {kind!r} is unknown: allowed {sorted(JOBS)}")
    module, function = JOBS[kind].split(":")
    return getattr(importlib.import_module(module), function)


def run_job(path: str) -> dict:
    """Run one job file; write and return its result dictionary (raises on failure after writing it)."""
    with open(path) as f:
        job = json.load(f)
    if not isinstance(job, dict) or not isinstance(job.get("out_dir"), str):
        raise JobError(f"job file {path!r} must hold a JSON object with a string 'out_dir'")
    out_dir = job["out_dir"]
    os.makedirs(out_dir, exist_ok=True)
    kind = job.get("kind")
    start = time.perf_counter()
    try:
        result = _handler(kind)(job, out_dir)
        record = {"kind": kind, "ok": True, "seconds": time.perf_counter() - start, "result": result}
    except Exception as exc:  # recorded for the caller, then re-raised: the exit status says it failed
        record = {"kind": kind, "ok": False, "error": f"{type(exc).__name__}: {exc}"}
        _write_json(os.path.join(out_dir, "result.json"), record)
        raise
    _write_json(os.path.join(out_dir, "result.json"), record)
    return record


def _write_json(path: str, data: dict) -> None:
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(data, f, indent=1)
    os.replace(tmp, path)


def main(argv: list[str]) -> int:
    if not argv:
        print("usage: worker.py JOB.json [JOB.json ...]", file=sys.stderr)
        return 2
    for path in argv:
        try:
            record = run_job(path)
        except JobError as exc:
            print(f"treefarm-blender: invalid job {path}: {exc}", file=sys.stderr)
            return 2
        except Exception:
            traceback.print_exc()
            print(f"treefarm-blender: job {path} failed", file=sys.stderr)
            return 1
        print(f"treefarm-blender: {record['kind']} done in {record['seconds']:.2f} s", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
