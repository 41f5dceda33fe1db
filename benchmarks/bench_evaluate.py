"""Evaluation speed: trees evaluated per second per method with 1 and 2 workers (target: 2 workers >= 1.8x).

Data: the printed evaluation spec (`farm evaluate --print-data-spec`) cut to --trees trees, generated once and cached
under ~/.cache/treefarm/bench-evaluate. One local Ray (2 CPUs) for the whole run, warmed by evaluating two trees per
method first, so each timing is the job itself without Ray's start-up. Trees/s: the trees phase (Ray tasks: the
tree rebuilt, the method, scoring with the default 20,000 surface samples, its row and panel written); the whole
job adds metrics.parquet, summary.md and the plots, a fixed cost on the driver (matplotlib).
No rotation sweep. The photos method (Blender + SfM, far slower) only with --methods ...,photos.

Run: python -m benchmarks.bench_evaluate [--trees 16] [--methods params,sketch-depth,two-view,cloud]
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import ray
import yaml

from benchmarks.harness import Benchmark, arguments, time_case
from farm.evaluate.job import evaluation_data_spec, plan_evaluation, run_evaluation
from farm.jobs import parse_spec
from farm.pipeline import WORKER_ENV, run_job

CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "treefarm" / "bench-evaluate"
TARGET = 1.8


def dataset(trees: int) -> Path:
    out = CACHE / f"eval-{trees}"
    if not (out / "manifest.json").exists():
        raw = yaml.safe_load(evaluation_data_spec())
        raw["trees"] = trees
        run_job(parse_spec(raw), str(out), progress=False)
    return out


def timed(data: Path, method: str, workers: int, trees: int | None) -> tuple[float, float, int]:
    """(seconds of the whole job, seconds of its trees phase, trees)."""
    plan = plan_evaluation([str(data)], [method], part="all", trees=trees)
    with tempfile.TemporaryDirectory(prefix="bench-evaluate-") as folder:
        job = time_case(lambda: run_evaluation(plan, Path(folder) / "report", workers=workers, sweep_step=None,
                                               progress=False), 1)
        seconds, outcome = job.median, job.result
    failed = int((outcome["rows"]["status"] != "ok").sum())
    if failed:
        print(f"  {method}: {failed} of {len(plan.units)} trees failed", flush=True)
    return seconds, outcome["seconds"]["trees"], len(plan.units)


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--trees", type=int, default=16)
    parser.add_argument("--methods", default="params,sketch-depth,two-view,cloud")
    args = parser.parse_args()
    bench = Benchmark("evaluate", "Evaluation jobs: trees per second per method on 1 and 2 workers", args)
    ray.init(num_cpus=2, include_dashboard=False, logging_level="WARNING", runtime_env={"env_vars": WORKER_ENV})
    data = dataset(args.trees)
    rows = []
    for method in [m for m in args.methods.split(",") if m]:
        timed(data, method, 2, 2)  # warm-up: worker processes, imports, networks
        one, one_trees, n = timed(data, method, 1, None)
        two, two_trees, _ = timed(data, method, 2, None)
        speedup = one_trees / two_trees
        rows.append([method, n, n / one_trees, n / two_trees, f"{speedup:.2f}x",
                     f"{one:.1f} / {two:.1f} s ({one / two:.2f}x)", "met" if speedup >= TARGET else "not met"])
        print(f"  {method}: {one:.1f} s with 1 worker ({one_trees:.1f} s of trees), {two:.1f} s with 2 "
              f"({two_trees:.1f} s)", flush=True)
    ray.shutdown()
    bench.table(f"{args.trees} trees of the evaluation spec per method",
                ["method", "trees", "trees/s, 1 worker", "trees/s, 2 workers", "2 workers / 1",
                 "whole job with its report, 1 / 2 workers", f"target >= {TARGET}x"], rows)
    bench.write()


if __name__ == "__main__":
    main()
