"""Training one task's network on Ray Train: data-parallel workers, a checkpoint every epoch, resume after a crash.

`train(task, data, ...)` is what `farm train` runs. The driver opens the dataset folders (`trainers.data`), splits
them by tree (or reapplies a frozen split), fits TreeSketchNet's codec on the training dictionaries, and hands Ray
Train's `TorchTrainer` a Ray Data dataset of the training views (decoded and preprocessed in Ray tasks, not
augmented). Each worker augments its rows per epoch with `default_rng([seed, epoch, index])` (the same draws as
`TaskDataset.record`), steps its network (DDP across workers), and rank 0 scores the validation views, appends a
row to `metrics.csv`, redraws `curves.png` and saves a checkpoint (weights, optimizers, epoch, step, the
network's noise generator) through `ray.train.report`. A run that stops (a crash, Ctrl-C, a lost node) resumes
from its last checkpoint when started again with the same run folder: Ray Train restores it, the loop continues
at the next epoch with the step count it recorded. After the fit the driver loads the last weights, scores the
held-out test views and the trivial baseline on them, and exports ONNX (`TrainResult`).

Determinism: on one CPU worker the same data, settings and seed give the same weights (torch's CPU kernels are
deterministic for these networks; the row order is Ray Data's, kept with `preserve_order`). With several workers
the rows each worker receives depend on Ray Data's streaming split timing, so runs agree in distribution, not in
bits; on GPUs cuDNN's convolution algorithms add run-to-run differences of float rounding.
"""
from __future__ import annotations

import copy
import json
import math
import os
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from farm.dataset import read_manifest
from species.errors import TreefarmError

from .curves import curves_png, read_metrics_csv, write_metrics_csv
from .data import Split, TaskDataset, TrainingData, open_data
from .networks import SettingsError, TaskNetwork, TrainSettings, network_for, schedule_factor
from .sketchnet_codec import ParameterCodec
from .tasks import Task, get_task

__all__ = ["train", "checked_split", "TrainResult", "TrainingError", "dataset_digests", "evaluation_batches",
           "RUN_FILES"]

RUN_FILES = {"metrics": "metrics.csv", "curves": "curves.png", "split": "split.json", "codec": "codec.json",
             "settings": "settings.json"}
_CHECKPOINT_FILE = "state.pt"
_EVAL_BATCH = 32
_DATA_CPUS = 0.5  # CPUs kept free for Ray Data's decoding tasks when the training workers would take them all


class TrainingError(TreefarmError):
    """A training run that cannot start or continue: no training views, a corrupt checkpoint, a run folder of
    another task or settings."""


@dataclass
class TrainResult:
    """A finished run: the network with its last weights, where its files are, and its held-out figures."""

    network: TaskNetwork
    run_dir: Path
    split: Split
    data: TrainingData
    epochs: int
    steps: int
    history: list[dict]
    test_metrics: dict[str, float]
    baseline_metrics: dict[str, float]
    summary: dict
    resumed_from_epoch: int | None = None
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------- records
def _codec_record(codec: ParameterCodec | None) -> Callable[[dict], dict]:
    """Per record: drop the strings, and (sketchnet) encode the dictionary with its species into target arrays."""
    def convert(record: dict) -> dict:
        out = {key: value for key, value in record.items() if isinstance(value, np.ndarray)}
        if codec is not None:
            params = json.loads(record["params_json"])
            params["species"] = record["species"]
            out.update(codec.encode(params))
        return out
    return convert


def _plain_rows(dataset: TaskDataset, indices: np.ndarray, codec: ParameterCodec | None) -> dict[str, np.ndarray]:
    """Plain (not augmented) records of `indices` in every style, as stacked numpy columns; `index` names each
    row so a worker can draw its augmentation. Styles after the first go in as `input@STYLE`."""
    convert = _codec_record(codec)
    columns: dict[str, list] = {"index": []}
    for i in indices:
        i = int(i)
        columns["index"].append(i)
        for k, style in enumerate(dataset.styles() if dataset.augment else dataset.styles()[:1]):
            record = convert(dataset.plain_record(i, style))
            if k == 0:
                for key, value in record.items():
                    columns.setdefault(key, []).append(value)
            else:
                columns.setdefault(f"input@{style}", []).append(record["input"])
    return {key: np.stack([np.asarray(v) for v in values]) for key, values in columns.items()}


def _augmented_batch(dataset: TaskDataset, rows: dict[str, np.ndarray], epoch: int) -> dict[str, np.ndarray]:
    """The rows of one training batch augmented for `epoch`: each row's style drawn and warped as
    `TaskDataset.record(index, epoch)` would (the same generator draws in the same order)."""
    out = {key: np.array(value, copy=True) for key, value in rows.items()}
    for r, index in enumerate(rows["index"]):
        style, rng = dataset.draw(int(index), epoch)
        key = "input" if style == dataset.styles()[0] else f"input@{style}"
        plain = {"input": rows[key][r]}
        if "target" in rows:
            plain.update(target=rows["target"][r], mask=rows["mask"][r])
        augmented = dataset.augmented(plain, rng)
        for name, value in augmented.items():
            out[name][r] = value
    return {key: value for key, value in out.items() if not key.startswith("input@")}


def evaluation_batches(dataset: TaskDataset, codec: ParameterCodec | None,
                       batch_size: int = _EVAL_BATCH) -> list[dict[str, np.ndarray]]:
    """Every view of a (not augmented) part as batches of numpy columns, in order."""
    order = np.arange(len(dataset))
    return [_plain_rows(dataset, order[i:i + batch_size], codec) for i in range(0, len(order), batch_size)]


# ---------------------------------------------------------------------------------------------- worker loop
def _worker_loop(config: dict) -> None:
    """Ray Train's per-worker loop (see the module docstring)."""
    import ray.train  # Ray Train: imported where training runs, so the rest of trainers loads without Ray
    import ray.train.torch

    torch.set_num_threads(max(1, int(config["threads_per_worker"])))
    settings = TrainSettings.from_dict(config["settings"])
    codec = ParameterCodec.from_dict(config["codec"]) if config["codec"] is not None else None
    network = network_for(config["task"], settings, codec).build()
    if config.get("warm_start"):
        network.load_state_dict(torch.load(config["warm_start"], map_location="cpu", weights_only=True))
    optimizers = network.optimizers()
    start_epoch, step, seconds_before = 0, 0, 0.0
    checkpoint = ray.train.get_checkpoint()
    if checkpoint is not None:
        with checkpoint.as_directory() as folder:
            state = _read_checkpoint(Path(folder) / _CHECKPOINT_FILE)
        network.load_state_dict(state["modules"])
        for name, optimizer in optimizers.items():
            optimizer.load_state_dict(state["optimizers"][name])
        network.noise.set_state(state["noise"])
        start_epoch, step, seconds_before = state["epoch"] + 1, state["step"], state["seconds"]
    context = ray.train.get_context()
    rank, world = context.get_world_rank(), context.get_world_size()
    for name in list(network.modules):
        network.modules[name] = ray.train.torch.prepare_model(network.modules[name]) if world > 1 \
            else network.modules[name]
    train_set: TaskDataset = config["train_dataset"]
    shard = ray.train.get_dataset_shard("train")
    val_batches = config["val_batches"] if rank == 0 else None
    run_dir = Path(config["run_dir"])
    progress = config.get("progress")
    started = time.perf_counter() - seconds_before  # a resumed run's clock continues where it stopped
    budget = settings.time_budget_s
    per_epoch = max(1, math.ceil(config["n_train"] / (settings.batch_size * world)))
    base_rate = network.learning_rate()
    for epoch in range(start_epoch, settings.epochs):
        losses: list[float] = []
        for rows in shard.iter_batches(batch_size=settings.batch_size, batch_format="numpy",
                                       local_shuffle_buffer_size=config["shuffle_buffer"],
                                       local_shuffle_seed=settings.seed * 100_003 + epoch):
            batch = _augmented_batch(train_set, rows, epoch)
            factor = schedule_factor(settings.schedule, step, per_epoch * settings.epochs)
            for optimizer in optimizers.values():
                for group in optimizer.param_groups:
                    group["lr"] = base_rate * factor
            losses.append(network.train_step(optimizers, batch)["loss"])
            step += 1
            if progress is not None and rank == 0:
                progress.put_nowait(("batch", epoch, len(losses), per_epoch, losses[-1]))
            if budget is not None and time.perf_counter() - started > budget:
                break
        stop = epoch + 1 >= settings.epochs or (budget is not None and time.perf_counter() - started > budget)
        row = {"epoch": epoch, "step": step, "train_loss": float(np.mean(losses)) if losses else float("nan"),
               "seconds": time.perf_counter() - started}
        with tempfile.TemporaryDirectory() as folder:
            saved = None
            if rank == 0:
                row.update({f"val_{k}": v for k, v in _unwrapped(network).metrics(val_batches).items()})
                _append_metrics(run_dir, row, config["baseline"], network.curve_metrics)
                torch.save({"modules": _unwrapped(network).state_dict(),
                            "optimizers": {n: o.state_dict() for n, o in optimizers.items()},
                            "noise": network.noise.get_state(), "epoch": epoch, "step": step,
                            "seconds": row["seconds"],
                            "settings": settings.to_dict(), "task": config["task"].name},
                           Path(folder) / _CHECKPOINT_FILE)
                saved = ray.train.Checkpoint.from_directory(folder)
            ray.train.report({k: v for k, v in row.items()}, checkpoint=saved)
        if progress is not None and rank == 0:
            progress.put_nowait(("epoch", epoch, row))
        if config.get("crash_after_epoch") == epoch and start_epoch == 0:  # the resume test's injected crash
            raise RuntimeError(f"injected crash after epoch {epoch}")
        if stop:
            break


def _unwrapped(network: TaskNetwork) -> TaskNetwork:
    """A view of the network with the DDP wrappers taken off its modules (for scoring and saving); the network
    itself keeps them, so every rank goes on stepping through DDP."""
    view = copy.copy(network)
    view.modules = {name: getattr(module, "module", module) for name, module in network.modules.items()}
    return view


def _read_checkpoint(path: Path) -> dict:
    try:
        return torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # noqa: BLE001 - torch raises many kinds for a damaged file
        raise TrainingError(f"checkpoint {path} cannot be read ({type(exc).__name__}: {exc}); delete the run "
                            f"folder {path.parent.parent} to start over") from None


def _append_metrics(run_dir: Path, row: dict, baseline: dict, shown: Sequence[str]) -> None:
    """Add an epoch's row to metrics.csv (dropping rows of later epochs a crashed run left) and redraw the
    curves: training loss, and each of `shown` on the validation views beside its baseline."""
    path = run_dir / RUN_FILES["metrics"]
    rows = [r for r in read_metrics_csv(path) if r["epoch"] < row["epoch"]] if path.exists() else []
    rows.append(row)
    write_metrics_csv(path, rows)
    panels = [("training loss", ["train_loss"])] + [(f"{name} (validation)", [f"val_{name}"]) for name in shown
                                                    if f"val_{name}" in row]
    (run_dir / RUN_FILES["curves"]).write_bytes(
        curves_png(rows, panels, {f"val_{k}": v for k, v in baseline.items()}, title=run_dir.name))


# ---------------------------------------------------------------------------------------------- driver
def dataset_digests(data: TrainingData) -> list[dict]:
    """Per dataset folder: its path, spec digest, code version and part checksums (from its manifest)."""
    out = []
    for source in data.sources:
        manifest = read_manifest(source.path)
        parts = {entry["path"]: entry["sha256"] for table in ("trees", "views")
                 for entry in manifest.get("parts", {}).get(table, [])}
        out.append({"path": str(source.path), "spec_digest": source.spec_digest,
                    "code_version": manifest.get("code_version"), "parts": parts})
    return out


def _check_run_folder(run_dir: Path, task: str, settings: TrainSettings, split: Split) -> int | None:
    """The last epoch a run folder recorded (None for a new folder); refuses one made for other settings."""
    record = run_dir / RUN_FILES["settings"]
    if not record.exists():
        return None
    stored = json.loads(record.read_text())
    mine = {"task": task, "settings": settings.to_dict()}
    if stored != mine:
        raise TrainingError(f"run folder {run_dir} belongs to another run ({stored}); give another --run-dir or "
                            f"remove it to start over")
    if (run_dir / RUN_FILES["split"]).exists() and Split.load(run_dir / RUN_FILES["split"]).parts != split.parts:
        raise TrainingError(f"run folder {run_dir} was trained on another split of the data; give another "
                            f"--run-dir")
    rows = read_metrics_csv(run_dir / RUN_FILES["metrics"]) if (run_dir / RUN_FILES["metrics"]).exists() else []
    return rows[-1]["epoch"] if rows else None


def checked_split(task: str | Task, training_data: TrainingData, frozen_split: Split | None = None) -> Split:
    """The split of `training_data` (by tree hash, or `frozen_split` reapplied) when each of its parts holds a tree;
    otherwise a TrainingError with the trees in each part and the task's `min_trees`. Cheap (hashes of tree ids),
    so `farm train` calls it before Ray starts."""
    task_spec = get_task(task)
    split = training_data.split(frozen=frozen_split)
    counts = {part: len(split.parts[part]) for part in ("train", "val", "test")}
    if all(counts.values()):
        return split
    trees = len(training_data.keys)
    raise TrainingError(
        f"{', '.join(map(str, training_data.paths))}: the split by tree puts {counts['train']} of the "
        f"{trees} usable tree{'' if trees == 1 else 's'} in train, {counts['val']} in validation and "
        f"{counts['test']} in test, and every part needs one: generate more trees (from {task_spec.min_trees} "
        f"trees the shipped spec {task_spec.spec_path.name} fills every part; docs/training.md)")


def train(task: str | Task, data: str | Sequence[str], *, settings: TrainSettings | None = None,
          run_dir: str | Path, workers: int = 1, gpus: int = 0, frozen_split: Split | None = None,
          warm_start: str | Path | None = None, codec: ParameterCodec | None = None, progress: bool = False,
          threads_per_worker: int | None = None, crash_after_epoch: int | None = None) -> TrainResult:
    """Train `task` on the dataset folders `data` (see the module docstring). Ray must be connected, or a local
    Ray is started. run_dir : the run's folder (Ray Train's storage; metrics.csv, curves.png, split.json);
    the same folder again resumes. frozen_split : a split to reapply (a retrain's champion split).
    warm_start : torch weights (`weights.pt` of a model) to start from. codec : TreeSketchNet's codec to keep
    (a retrain keeps the champion's normalisation); fitted on the training dictionaries otherwise.
    threads_per_worker : torch threads in each worker (default: the cluster's CPUs shared among the workers)."""
    import ray  # Ray: imported where training runs, so the rest of trainers loads without it
    import ray.data
    import ray.train
    from ray.train.torch import TorchTrainer

    settings = settings or TrainSettings()
    task_spec = get_task(task)
    if workers < 1 or gpus < 0:
        raise SettingsError(f"workers = {workers}, gpus = {gpus} is invalid: allowed workers >= 1, gpus >= 0")
    started = time.perf_counter()
    training_data = open_data(task_spec, data)
    split = checked_split(task_spec, training_data, frozen_split)
    train_set = TaskDataset(training_data, split, "train", augment=True, seed=settings.seed)
    val_set = TaskDataset(training_data, split, "val")
    test_set = TaskDataset(training_data, split, "test")
    if task_spec.network == "sketchnet" and codec is None:
        trees = {key: training_data.params_of(key) for key in split.parts["train"]}
        codec = ParameterCodec.fit(list(trees.values()))
    run_dir = Path(run_dir).resolve()
    run_dir.mkdir(parents=True, exist_ok=True)
    last_epoch = _check_run_folder(run_dir, task_spec.name, settings, split)
    if last_epoch is not None:
        # a damaged checkpoint is said here, before Ray Train spends tens of seconds starting workers to find it
        saved = sorted((run_dir / "ray_train").glob(f"checkpoint_*/{_CHECKPOINT_FILE}"))
        if saved:
            _read_checkpoint(saved[-1])
    split.save(run_dir / RUN_FILES["split"])
    (run_dir / RUN_FILES["settings"]).write_text(json.dumps({"task": task_spec.name,
                                                             "settings": settings.to_dict()}))
    if codec is not None:
        (run_dir / RUN_FILES["codec"]).write_text(json.dumps(codec.to_dict(), sort_keys=True))

    network = network_for(task_spec, settings, codec).build()
    val_batches = evaluation_batches(val_set, codec)
    reference = _baseline_reference(network, train_set, codec)
    baseline_val = _baseline(network, val_batches, reference)
    if not ray.is_initialized():
        ray.init(include_dashboard=False, logging_level="WARNING")
    context = ray.data.DataContext.get_current()
    context.execution_options.preserve_order = True
    context.enable_progress_bars = False
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    # Ray Data's decoding tasks need CPU beside the training workers: where the workers would take every CPU,
    # each takes a little less, so the tasks (a quarter CPU each) always find room and training never starves.
    worker_cpus = 1.0 if workers + _DATA_CPUS <= cpus else max(0.25, (cpus - _DATA_CPUS) / workers)
    # The indices are made here (ray.data.range's read tasks would each ask for a whole CPU).
    train_rows = ray.data.from_numpy(np.arange(len(train_set))) \
        .map_batches(lambda batch: _plain_rows(train_set, batch["data"], codec), batch_size=32,
                     batch_format="numpy", num_cpus=_DATA_CPUS / 2)
    queue = _progress_queue() if progress else None
    # The task itself, not its name: a worker builds its network from this record, whatever its own TASKS holds.
    config = {"task": task_spec, "settings": settings.to_dict(),
              "codec": None if codec is None else codec.to_dict(), "train_dataset": train_set,
              "val_batches": val_batches, "baseline": baseline_val, "run_dir": str(run_dir),
              "n_train": len(train_set), "shuffle_buffer": max(64, min(len(train_set), 4096)),
              "threads_per_worker": threads_per_worker or max(1, cpus // workers if not gpus else 1),
              "warm_start": None if warm_start is None else str(warm_start), "progress": queue,
              "crash_after_epoch": crash_after_epoch}
    trainer = TorchTrainer(
        _worker_loop, train_loop_config=config, datasets={"train": train_rows},
        scaling_config=ray.train.ScalingConfig(num_workers=workers, use_gpu=gpus > 0,
                                               resources_per_worker={"CPU": worker_cpus,
                                                                     **({"GPU": gpus / workers} if gpus else {})}),
        run_config=ray.train.RunConfig(name="ray_train", storage_path=str(run_dir),
                                       checkpoint_config=ray.train.CheckpointConfig(num_to_keep=2),
                                       failure_config=ray.train.FailureConfig(max_failures=0)))
    try:
        result = _fit(trainer, queue, settings, len(train_set), workers, last_epoch)
        if result.error is not None:
            raise result.error
    except Exception as exc:  # noqa: BLE001 - a worker's user error (a corrupt checkpoint, bad data) comes back
        raise _worker_user_error(exc) or exc  # wrapped; it is shown as its own one line
    if result.checkpoint is None:
        raise TrainingError(f"training {task_spec.name} in {run_dir} ended without a checkpoint")
    with result.checkpoint.as_directory() as folder:
        state = _read_checkpoint(Path(folder) / _CHECKPOINT_FILE)
    network.load_state_dict(state["modules"])
    test_batches = evaluation_batches(test_set, codec)
    history = read_metrics_csv(run_dir / RUN_FILES["metrics"])
    return TrainResult(network=network, run_dir=run_dir, split=split, data=training_data, epochs=state["epoch"] + 1,
                       steps=state["step"], history=history, test_metrics=network.metrics(test_batches),
                       baseline_metrics=_baseline(network, test_batches, reference),
                       summary=training_data.summary(split, frozen_split), resumed_from_epoch=last_epoch,
                       seconds=time.perf_counter() - started)


def _baseline_reference(network: TaskNetwork, train_set: TaskDataset, codec) -> np.ndarray | None:
    """What the trivial baseline predicts from the training views: None for TreeSketchNet (its codec holds the
    training means), else the mean depth per channel of (a sample of) the training views, decoded once."""
    if network.family == "sketchnet":
        return None
    sample = np.linspace(0, len(train_set) - 1, min(len(train_set), 256)).astype(int)
    plain = copy.copy(train_set)
    plain.augment = False
    return network.mean_depth([_plain_rows(plain, sample, codec)])


def _baseline(network: TaskNetwork, batches, reference: np.ndarray | None) -> dict[str, float]:
    """The trivial baseline's metrics on `batches` (mean parameters, or `reference`'s mean depth)."""
    if reference is None:
        return network.baseline_metrics(batches)
    return network.baseline_metrics(batches, reference)


def _worker_user_error(exc: BaseException) -> TreefarmError | None:
    """The TreefarmError a worker raised, out of Ray Train's WorkerGroupError (None when it was something else)."""
    for failure in getattr(exc, "worker_failures", {}).values():
        cause = failure
        while cause is not None and not isinstance(cause, TreefarmError):
            cause = getattr(cause, "cause", None) or cause.__cause__
        if isinstance(cause, TreefarmError):
            return cause
    return None


def _progress_queue():
    from ray.util.queue import Queue

    return Queue(maxsize=10_000)


def _fit(trainer, queue, settings: TrainSettings, n_train: int, workers: int, last_epoch: int | None):
    """trainer.fit() in a thread while this one draws the progress bar from the workers' messages."""
    outcome: dict[str, Any] = {}

    def run() -> None:
        try:
            outcome["result"] = trainer.fit()
        except BaseException as exc:  # noqa: BLE001 - handed to the calling thread
            outcome["error"] = exc

    thread = threading.Thread(target=run, name="ray-train-fit", daemon=True)
    thread.start()
    bar = None
    if queue is not None:
        from tqdm import tqdm

        per_epoch = max(1, math.ceil(n_train / (settings.batch_size * workers)))
        done = 0 if last_epoch is None else (last_epoch + 1) * per_epoch
        bar = tqdm(total=settings.epochs * per_epoch, initial=done, unit="batch", desc="train", dynamic_ncols=True)
    while thread.is_alive():
        thread.join(timeout=0.25)
        while queue is not None and not queue.empty():
            message = queue.get_nowait()
            if message[0] == "batch":
                _, epoch, batch, per_epoch, loss = message
                bar.n = epoch * per_epoch + batch
                bar.set_postfix(epoch=epoch, loss=f"{loss:.4g}")
                bar.refresh()
            else:
                _, epoch, row = message
                bar.set_postfix({"epoch": epoch, **{k: f"{v:.4g}" for k, v in row.items()
                                                    if k.startswith("val_")}})
    if bar is not None:
        bar.close()
    if "error" in outcome:
        raise outcome["error"]
    return outcome["result"]
