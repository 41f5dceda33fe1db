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
`trainers.tasks.TASKS`. A task's dataset is `--data-root/TASK`; with `--generate N`, a missing one is made here:
N trees of the task's shipped spec. The tables go to benchmarks/results/train.json (train_throughput.json with
--skip-quality), the quality reports to --work/bench_train.json.

Run: python -m benchmarks.bench_train --data-root out/train-full [--budget 600] [--export-models models]
     python -m benchmarks.bench_train --skip-quality --generate 40 --data-root out/bench-train-data   (throughput)
"""
from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

# No thread pinning: each throughput setting sets its own torch threads (`train(threads_per_worker=...)`), and the
# quality runs use every core.
from benchmarks.harness import ROOT, Benchmark, arguments
from farm.jobs import load_spec
from farm.pipeline import ray_connection, run_job
from trainers.data import TaskDataset
from trainers.models import model_files
from trainers.networks import TrainSettings
from trainers.sketchnet import grown_tree_errors
from trainers.tasks import TASKS
from trainers.training import train

# Published figures after full training (seeds-digest 1.13 and 4.5) and our targets, for the shipped tasks; a task
# without them gets no such line.
REFERENCES = {"pix2pix-silhouette": "thesis 0.041 after 4 days on a GTX 1080 Ti, 20,000 pairs",
              "pix2pix-trunk": "thesis 0.032 after 4 days on a GTX 1080 Ti, 20,000 pairs",
              "sketchnet": "paper: 2,000 epochs, batch 8, Adam 1e-5; target here >= 95 % species accuracy",
              "tree-mask": "issue 51: masks on renders at IoU >= 0.9 against the renderer's"}
TARGETS = {"pix2pix-silhouette": "error >= 30 % below the baseline's", "pix2pix-trunk": "error >= 30 % below "
           "the baseline's", "sketchnet": ">= 95 % species, every head above the baseline",
           "tree-mask": "mask IoU >= 0.9 on held-out renders"}
TARGET_SCALING = 1.7  # 2 workers of 1 thread against 1 worker of 1 thread
SETTINGS = ((1, 1), (1, 2), (2, 1))  # (workers, torch threads each) of the throughput table


def throughput(task: str, data: list[str], seconds: float, work: Path) -> list[list]:
    """Rows (network, workers, threads each, samples, samples/s, against 1 worker x 1 thread) of each setting."""
    rows = []
    for workers, threads in SETTINGS:
        settings = TrainSettings(epochs=1000, time_budget_s=seconds, seed=0)
        result = train(task, data, settings=settings, run_dir=work / f"{task}-{workers}x{threads}",
                       workers=workers, threads_per_worker=threads)
        samples = result.steps * settings.batch_size * workers
        rows.append([task, workers, threads, samples, samples / result.history[-1]["seconds"]])
    single = rows[0][4]
    return [[*row, f"{row[4] / single:.2f}x"] for row in rows]


def throughput_table(bench: Benchmark, tasks: list[str], args) -> None:
    rows = []
    for task in tasks:
        rows += throughput(task, [str(args.data_root / task)], args.throughput_seconds, args.work)
    bench.table(f"training throughput, {args.throughput_seconds:.0f} s per setting (start-up included)",
                ["network", "workers", "threads each", "samples", "samples/s", "vs 1x1"], rows,
                [f"target: 2 workers >= {TARGET_SCALING}x one single-threaded worker"])
    for task in tasks:
        by_setting = {(row[1], row[2]): row[4] for row in rows if row[0] == task}
        bench.figure(f"{task}: samples/s, 2 workers", by_setting[2, 1], "samples/s",
                     f"1 worker {by_setting[1, 1]:.2f}; {by_setting[2, 1] / by_setting[1, 1]:.2f}x, target >= "
                     f"{TARGET_SCALING}x")


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
    keys = ["depth_error"] if "depth_error" in test else ["mask_iou"] if "mask_iou" in test else [
        "accuracy_species", "score_overall"] + sorted(
        k for k in test if k.startswith("score_") and k != "score_overall") + sorted(
        k for k in test if k.startswith("grown_"))
    for key in keys:
        rows.append([report["task"], key, f"{test[key]:.4g}", f"{base.get(key, float('nan')):.4g}",
                     f"{report['epochs']} ep / {report['steps']} steps / {report['seconds']:.0f} s"])
    return rows


def generate(task: str, folder: Path, trees: int) -> None:
    """`trees` trees of the task's shipped spec into `folder` (Ray connected)."""
    print(f"generating {trees} trees of {TASKS[task].spec_path.relative_to(ROOT)} into {folder}", flush=True)
    run_job(load_spec(TASKS[task].spec_path).with_trees(trees), str(folder), progress=False)


def option_parser():
    """The benchmark's options; `--tasks` defaults to every task of the registry."""
    parser = arguments(__doc__)
    parser.add_argument("--data-root", type=Path, default=ROOT / "out" / "train-full",
                        help="folder with one dataset per task (named as the task)")
    parser.add_argument("--tasks", default=",".join(TASKS), help="comma-separated names of trainers.tasks.TASKS")
    parser.add_argument("--budget", type=float, default=600.0,
                        help="training seconds per network; 0: no time limit, the recipe's epochs only (make models)")
    parser.add_argument("--throughput-seconds", type=float, default=40.0)
    parser.add_argument("--skip-throughput", action="store_true")
    parser.add_argument("--skip-quality", action="store_true", help="only the throughput table")
    parser.add_argument("--generate", type=int, default=0, metavar="N",
                        help="make a task's missing dataset here: N trees of its shipped spec")
    parser.add_argument("--export-models", type=Path, help="write the trained networks as model folders here")
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "bench_train")
    return parser


def main(argv: list[str] | None = None) -> None:
    args = option_parser().parse_args(argv)
    tasks = [t for t in args.tasks.split(",") if t]
    for task in tasks:
        if task not in TASKS:
            sys.exit(f"task {task!r} is unknown: allowed {', '.join(TASKS)}")
        if not args.generate and not (args.data_root / task / "manifest.json").exists():
            sys.exit(f"no {task} dataset in {args.data_root / task}: farm generate "
                     f"{TASKS[task].spec_path.relative_to(ROOT)} --out {args.data_root / task} (or --generate N)")
    if args.skip_quality:
        bench = Benchmark("train_throughput", "Training throughput on CPU: samples per second on 1 and 2 Ray workers",
                          args)
    else:
        bench = Benchmark("train", "Training on CPU: samples per second on 1 and 2 Ray workers, held-out quality",
                          args)
    if args.work.exists():
        shutil.rmtree(args.work)
    args.work.mkdir(parents=True)
    with ray_connection(log_to_driver=False):
        for task in tasks:
            if not (args.data_root / task / "manifest.json").exists():
                generate(task, args.data_root / task, args.generate)
        if not args.skip_throughput:
            throughput_table(bench, tasks, args)
        reports = [] if args.skip_quality else [
            quality(task, [str(args.data_root / task)], args.budget, args.work, args.export_models) for task in tasks]
    if reports:
        bench.table(f"held-out quality after {args.budget:.0f} s of training per network (one worker, every core)",
                    ["network", "metric", "model", "baseline", "trained"],
                    [row for report in reports for row in quality_rows(report)],
                    [f"{task}: target {TARGETS[task]}; reference {REFERENCES[task]}" for task in tasks
                     if task in TARGETS])
        (args.work / "bench_train.json").write_text(json.dumps(reports, indent=1, sort_keys=True))
    bench.write()


if __name__ == "__main__":
    main()
