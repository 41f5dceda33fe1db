"""Training speed and quality of the three networks on CPU, beside the trivial baselines and the papers' figures.

1. Throughput: training samples per second per network with 1 Ray worker (1 and 2 torch threads) and with 2
   workers (1 thread each), over a short fixed budget (target: 2 workers >= 1.7x one single-threaded worker).
2. Quality after a fixed budget of CPU time per network (default 10 minutes, one worker with every core) on the
   datasets the shipped specs make (`farm generate trainers/specs/TASK.yaml`), scored on held-out trees beside
   the baseline (mean parameters; mean depth) on the same split: TreeSketchNet's (1 - RMSE) x 100 per head and
   species accuracy, the depth networks' mean absolute depth error over the foreground.
3. `--export-models DIR` writes each trained network as a model folder (ONNX, torch weights, codec, split,
   metrics, curves): `make models` exports into `models/`, the defaults `farm reconstruct` loads.

The tasks, and the budget recipe each trains with (`Task.recipe`, the shipped default models'), are
`trainers.tasks.TASKS`.

Run: .venv/bin/python benchmarks/bench_train.py --data-root out/train-full [--budget 600] [--export-models models]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from farm.pipeline import ray_connection  # noqa: E402
from farm.table import format_table  # noqa: E402
from trainers.data import TaskDataset  # noqa: E402
from trainers.models import model_files  # noqa: E402
from trainers.networks import TrainSettings  # noqa: E402
from trainers.sketchnet import grown_tree_errors  # noqa: E402
from trainers.tasks import TASKS  # noqa: E402
from trainers.training import train  # noqa: E402

# Published figures after full training (seeds-digest 1.13 and 4.5) and our targets, for the shipped tasks; a task
# without them gets no such line.
REFERENCES = {"pix2pix-silhouette": "thesis 0.041 after 4 days on a GTX 1080 Ti, 20,000 pairs",
              "pix2pix-trunk": "thesis 0.032 after 4 days on a GTX 1080 Ti, 20,000 pairs",
              "sketchnet": "paper: 2,000 epochs, batch 8, Adam 1e-5; target here >= 95 % species accuracy"}
TARGETS = {"pix2pix-silhouette": "error >= 30 % below the baseline's", "pix2pix-trunk": "error >= 30 % below "
           "the baseline's", "sketchnet": ">= 95 % species, every head above the baseline"}

def throughput(task: str, data: list[str], seconds: float, work: Path) -> list[list]:
    rows = []
    for workers, threads in ((1, 1), (1, 2), (2, 1)):
        settings = TrainSettings(epochs=1000, time_budget_s=seconds, seed=0)
        result = train(task, data, settings=settings, run_dir=work / f"{task}-{workers}x{threads}",
                       workers=workers, threads_per_worker=threads)
        last = result.history[-1]
        rate = result.steps * settings.batch_size * workers / last["seconds"]
        rows.append([task, workers, threads, result.steps * settings.batch_size * workers, f"{rate:.2f}"])
    single = float(rows[0][4])
    for row in rows:
        row.append(f"{float(row[4]) / single:.2f}x")
    return rows


def grown_errors(result, limit: int = 400) -> dict:
    """TreeSketchNet's dictionaries grown (`trainers.sketchnet.grown_tree_errors`, one fixed seed for both): height
    and crown radius of the trees of its predictions on the held-out views (at most `limit`), and of the
    mean-parameter baseline's, against the true trees', as {"test"|"baseline": {"grown_<error>": value}}."""
    network = result.network
    test_set = TaskDataset(result.data, result.split, "test")
    records = [test_set.plain_record(i) for i in range(min(len(test_set), limit))]
    inputs = np.stack([r["input"] for r in records])
    outputs = [network.predict(inputs[i:i + 32]) for i in range(0, len(inputs), 32)]
    joined = {key: torch.cat([o[key] for o in outputs]) for key in outputs[0]}
    true = [{**json.loads(r["params_json"]), "species": r["species"]} for r in records]
    model = grown_tree_errors(network.codec.decode_batch(joined), true)
    baseline = grown_tree_errors(network.codec.decode_arrays(network.codec.baseline_outputs(len(true))), true)
    return {side: {f"grown_{key}": errors[key] for key in ("height_rel_error", "crown_radius_rel_error")}
            for side, errors in (("test", model), ("baseline", baseline))}


def quality(task: str, data: list[str], budget: float, work: Path, export: Path | None) -> dict:
    settings = TrainSettings(**{"epochs": 1000, "time_budget_s": budget or None, "seed": 0, **TASKS[task].recipe})
    started = time.perf_counter()
    result = train(task, data, settings=settings, run_dir=work / f"{task}-quality", workers=1, progress=True)
    out = {"task": task, "seconds": time.perf_counter() - started, "epochs": result.epochs, "steps": result.steps,
           "test": result.test_metrics, "baseline": result.baseline_metrics, "data": result.summary}
    if TASKS[task].network == "sketchnet":
        grown = grown_errors(result)
        out["test"], out["baseline"] = {**out["test"], **grown["test"]}, {**out["baseline"], **grown["baseline"]}
    if export is not None:
        folder = export / task
        with tempfile.TemporaryDirectory() as staging:
            files = model_files(result, Path(staging) / task)
            for name, path in files.items():
                (Path(staging) / task).mkdir(exist_ok=True)
                if path.parent != Path(staging) / task:
                    shutil.copy2(path, Path(staging) / task / name)
            result.split.save(Path(staging) / task / "split.json")
            (Path(staging) / task / "metrics_report.json").write_text(json.dumps(out, indent=1, sort_keys=True))
            if folder.exists():
                shutil.rmtree(folder)
            shutil.copytree(Path(staging) / task, folder)
    return out


def quality_rows(report: dict) -> list[list]:
    rows = []
    test, base = report["test"], report["baseline"]
    keys = ["depth_error"] if "depth_error" in test else ["accuracy_species", "score_overall"] + sorted(
        k for k in test if k.startswith("score_") and k != "score_overall") + sorted(
        k for k in test if k.startswith("grown_"))
    for key in keys:
        rows.append([report["task"], key, f"{test[key]:.4g}", f"{base.get(key, float('nan')):.4g}",
                     f"{report['epochs']} ep / {report['steps']} steps / {report['seconds']:.0f} s"])
    return rows


def arguments() -> argparse.ArgumentParser:
    """The benchmark's options; `--tasks` defaults to every task of the registry."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-root", type=Path, default=ROOT / "out" / "train-full",
                        help="folder with one dataset per task (named as the task)")
    parser.add_argument("--tasks", default=",".join(TASKS), help="comma-separated names of trainers.tasks.TASKS")
    parser.add_argument("--budget", type=float, default=600.0,
                        help="training seconds per network; 0: no time limit, the recipe's epochs only (make models)")
    parser.add_argument("--throughput-seconds", type=float, default=40.0)
    parser.add_argument("--skip-throughput", action="store_true")
    parser.add_argument("--skip-quality", action="store_true", help="only the throughput table")
    parser.add_argument("--export-models", type=Path, help="write the trained networks as model folders here")
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "bench_train")
    return parser


def main(argv: list[str] | None = None) -> None:
    args = arguments().parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    for task in tasks:
        if task not in TASKS:
            sys.exit(f"task {task!r} is unknown: allowed {', '.join(TASKS)}")
        if not (args.data_root / task / "manifest.json").exists():
            sys.exit(f"no {task} dataset in {args.data_root / task}: farm generate "
                     f"{TASKS[task].spec_path.relative_to(ROOT)} --out {args.data_root / task}")
    if args.work.exists():
        shutil.rmtree(args.work)
    args.work.mkdir(parents=True)
    with ray_connection(log_to_driver=False):
        if not args.skip_throughput:
            rows = []
            for task in tasks:
                rows += throughput(task, [str(args.data_root / task)], args.throughput_seconds, args.work)
            print(f"\ntraining throughput, {os.cpu_count()} cores, {args.throughput_seconds:.0f} s per setting "
                  f"(start-up included)")
            print(format_table(["network", "workers", "threads each", "samples", "samples/s", "vs 1x1"], rows))
        reports = [] if args.skip_quality else [
            quality(task, [str(args.data_root / task)], args.budget, args.work, args.export_models) for task in tasks]
    if not reports:
        return
    rows = [row for report in reports for row in quality_rows(report)]
    print(f"\nheld-out quality after {args.budget:.0f} s of training per network (one worker, every core)")
    print(format_table(["network", "metric", "model", "baseline", "trained"], rows))
    for task in tasks:
        if task in TARGETS:
            print(f"  {task}: target {TARGETS[task]}; reference {REFERENCES[task]}")
    (args.work / "bench_train.json").write_text(json.dumps(reports, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
