"""Trained models in the registry: register a run, load a predictor, retrain a challenger against the champion.

- `register_result(registry, result)` logs a finished `TrainResult` as a new version of its task's model: the
  weights (`weights.pt`), the ONNX file, the codec's normalisation (TreeSketchNet), the split, the held-out metrics
  beside the trivial baseline's on the same split (`X` and `X_baseline`), the metrics history and curves, the
  datasets' spec digests and part checksums, the settings and the code version. It becomes `latest`; `promote`
  makes it `champion` (a first version is promoted at once, unless it scores worse than its baseline: then only
  when forced).
- `load(name, models=None)` gives a `Predictor` from the registry (`champion`, else `latest`), or from the default
  models shipped in `models/` when no registry is given; it runs the ONNX file with ONNX Runtime, needs neither Ray
  nor torch, and checks the file's inputs and outputs and the codec version against what this code expects.
- `retrain(task, data, registry)` trains a challenger from the champion's weights (or the shipped default's) on all
  the data with the champion's frozen split, scores challenger and champion on the same held-out views, registers
  the challenger, promotes it only if it is better, and writes a report (Markdown and JSON) saying why.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Sequence

import numpy as np

from species.errors import TreefarmError

from .onnx_runtime import OnnxModel
from .preprocess import KINDS, prepare, preprocess
from .model_tables import below_baseline
from .registry import BASELINE_SUFFIX, SHIPPED, ModelVersion, Registry, RegistryError, open_registry
from .sketchnet_codec import CODEC_VERSION, ParameterCodec
from .tasks import Task, get_task

__all__ = ["register_result", "load", "Predictor", "retrain", "RetrainOutcome", "DEFAULT_MODELS",
           "ModelFilesError", "model_files", "shipped_models", "holds_shipped_models", "counted"]

DEFAULT_MODELS = Path(__file__).resolve().parents[1] / "models"  # the shipped defaults, one folder per task
_MANIFEST = "model.json"  # what a model folder is: task, files, input size, codec version


class ModelFilesError(TreefarmError):
    """A model folder that lacks a file, holds another task's model, or a codec of another version."""


# ---------------------------------------------------------------------------------------------- register
def model_files(result, folder: Path) -> dict[str, Path]:
    """Export a trained result's files into `folder`: the network's (ONNX, weights, codec), the run's metrics and
    curves, and `model.json` (what the predictor needs to know)."""
    folder.mkdir(parents=True, exist_ok=True)
    network = result.network
    files = network.export(folder)
    onnx = next(name for name in files if name.endswith(".onnx"))
    manifest = {"task": network.task.name, "onnx": onnx, "input_size": network.task.input_size,
                "input_kind": network.task.input_kind, "settings": network.settings.to_dict(),
                "codec_version": CODEC_VERSION if network.family == "sketchnet" else None}
    (folder / _MANIFEST).write_text(json.dumps(manifest, indent=1, sort_keys=True))
    files[_MANIFEST] = folder / _MANIFEST
    for name in ("metrics.csv", "curves.png"):
        if (result.run_dir / name).exists():
            files[name] = result.run_dir / name
    return files


def _logged_metrics(result) -> dict[str, float]:
    metrics = {k: float(v) for k, v in result.test_metrics.items() if np.isfinite(v)}
    metrics.update({f"{k}{BASELINE_SUFFIX}": float(v) for k, v in result.baseline_metrics.items() if np.isfinite(v)})
    return metrics


def register_result(registry: Registry, result, *, code_version: str = "unknown", promote: bool | None = None,
                    force: bool = False, datasets: list[dict] | None = None, extra_blobs: dict | None = None):
    """Register `result` as a new version of its task's model (see the module docstring); `promote` None promotes
    it when the model has no champion yet and it is not worse than its baseline (`registry.below_baseline`), or
    `force`. Returns the ModelVersion."""
    from .training import dataset_digests  # torch's training loop: the predictor (ONNX Runtime) loads without it

    task = result.network.task
    with tempfile.TemporaryDirectory() as folder:
        files = model_files(result, Path(folder))
        blobs = {"split": json.loads(result.split.to_json()), "data_summary": result.summary,
                 "datasets": datasets if datasets is not None else dataset_digests(result.data),
                 "metrics_report": {"test": result.test_metrics, "baseline": result.baseline_metrics,
                                    "history": result.history, "epochs": result.epochs, "steps": result.steps,
                                    "primary": result.network.primary,
                                    "higher_is_better": result.network.higher_is_better}}
        # TreeSketchNet's codec is a file of the model (codec.json), so `load_json(name, v, "codec")` reads it.
        blobs.update(extra_blobs or {})
        params = {f"setting_{k}": v for k, v in result.network.settings.to_dict().items()}
        params.update(epochs=result.epochs, steps=result.steps, train_trees=result.summary["trees"]["train"],
                      rejected_trees=result.summary["rejected"])
        version = registry.register(task.model_name, files, metrics=_logged_metrics(result), params=params,
                                    tags={"task": task.name, "code_version": code_version,
                                          "primary_metric": result.network.primary},
                                    json_blobs=blobs)
    if promote or (promote is None and registry.champion(task.model_name) is None
                   and (force or below_baseline(version) is None)):
        version = registry.promote(task.model_name, version.version)
    return version


# ---------------------------------------------------------------------------------------------- shipped
def holds_shipped_models(folder: str | Path) -> bool:
    """Whether `folder` is a folder of model folders (each with model.json), as `models/` is."""
    folder = Path(folder)
    return folder.is_dir() and any((child / _MANIFEST).is_file() for child in folder.iterdir())


def shipped_models(folder: str | Path = DEFAULT_MODELS) -> list[ModelVersion]:
    """The model folders in `folder` (default: the shipped `models/`) as registry versions, sorted by name: alias
    `shipped`, version 0, the held-out metrics of their metrics_report.json beside the baseline's (`X_baseline`),
    the settings as params. Only reads."""
    found = []
    for manifest_path in sorted(Path(folder).glob(f"*/{_MANIFEST}")):
        manifest = json.loads(manifest_path.read_text())
        report_path = manifest_path.parent / "metrics_report.json"
        report = json.loads(report_path.read_text()) if report_path.exists() else {}
        metrics = {k: float(v) for k, v in report.get("test", {}).items() if v is not None and np.isfinite(v)}
        metrics.update({f"{k}{BASELINE_SUFFIX}": float(v) for k, v in report.get("baseline", {}).items()
                        if v is not None and np.isfinite(v)})
        found.append(ModelVersion(
            name=get_task(manifest["task"]).model_name, version=0, aliases=(SHIPPED,), run_id="",
            metrics=metrics, params={k: str(v) for k, v in manifest.get("settings", {}).items()},
            tags={"task": manifest["task"]}, source=str(manifest_path.parent),
            created=datetime.fromtimestamp(manifest_path.stat().st_mtime, timezone.utc)))
    return found


# ---------------------------------------------------------------------------------------------- predictor
@dataclass
class Predictor:
    """A trained network ready for inference: `predict(image)` takes a drawing (any size; scanned, tablet or
    rendered, as `trainers.preprocess` reads them) and gives a parameter dictionary (TreeSketchNet, grown by
    `species.grow`), depth maps (pix2pix: float32 (C, S, S) on [0, 1], the channels of the task's target) or tree
    probabilities (segment: float32 (1, S, S) of the photo centred in a square; `reconstruct.photo_masks` runs the
    model on a photo at its own aspect)."""

    task: str
    folder: Path
    model: OnnxModel
    input_size: int
    input_kind: str
    codec: ParameterCodec | None
    source: str

    def prepare(self, image) -> np.ndarray:
        """The network's input for `image`: (C, S, S) float32, as training saw its sketches."""
        return preprocess(image, self.input_kind, self.input_size)

    def predict(self, image, seed: int = 0):
        return self.predict_view(image, seed)[0]

    def predict_view(self, image, seed: int = 0):
        """`predict` with the network's input (`trainers.preprocess.Prepared`: the image and the crop of `image`
        it was cut from), so a depth map can be placed back on the drawing, or beside another network's of the
        same drawing, and the input shown without preprocessing the drawing again."""
        outputs, prepared = self.outputs_view(image)
        if self.codec is None:
            return np.asarray(outputs)[0], prepared
        return self.codec.decode_arrays(dict(outputs), seed=seed)[0], prepared

    def outputs_view(self, image):
        """The network's raw outputs for `image` (a batch of one; TreeSketchNet's by head name, for the codec's
        `decode_arrays` and `species_confidence`) and its input (`trainers.preprocess.Prepared`)."""
        prepared = prepare(image, self.input_kind, self.input_size)
        return self.model.run(prepared.image[None]), prepared

    def __repr__(self) -> str:
        return f"Predictor({self.task}, {self.source})"


def _expected_signature(task: Task, size: int, codec: ParameterCodec | None) -> tuple[dict, dict]:
    if task.network == "segment":  # fully convolutional: any height and width
        return {"photo": (None, KINDS[task.input_kind], None, None)}, {"mask": (None, task.out_channels, None, None)}
    inputs = {"sketch": (None, KINDS[task.input_kind], size, size)}
    if codec is not None:
        return inputs, {name: (None, n) for name, n in codec.output_sizes.items()}
    return inputs, {"depth": (None, task.out_channels, size, size)}


def predictor_from_folder(folder: str | Path, task: str | None = None, source: str | None = None) -> Predictor:
    """A predictor of the model files in `folder` (a downloaded registry version or a shipped default)."""
    folder = Path(folder)
    manifest_path = folder / _MANIFEST
    if not manifest_path.exists():
        raise ModelFilesError(f"{folder} holds no treefarm model ({_MANIFEST} is missing)")
    manifest = json.loads(manifest_path.read_text())
    if task is not None and manifest["task"] != task:
        raise ModelFilesError(f"{folder} holds a {manifest['task']} model, not {task}")
    spec = get_task(manifest["task"])
    codec = None
    if spec.network == "sketchnet":
        if manifest.get("codec_version") != CODEC_VERSION:
            raise ModelFilesError(f"{folder}: the model's codec is {manifest.get('codec_version')!r}, this code "
                                  f"reads {CODEC_VERSION!r}; retrain it (farm train sketchnet)")
        codec_path = folder / "codec.json"
        if not codec_path.exists():
            raise ModelFilesError(f"{folder}: codec.json is missing beside the TreeSketchNet model")
        codec = ParameterCodec.from_dict(json.loads(codec_path.read_text()))
    size = int(manifest["input_size"])
    inputs, outputs = _expected_signature(spec, size, codec)
    model = OnnxModel(folder / manifest["onnx"], inputs, outputs)
    return Predictor(manifest["task"], folder, model, size, manifest["input_kind"], codec, source or str(folder))


def load(name: str, models: str | Path | Registry | None = None, version: int | str | None = None) -> Predictor:
    """The predictor of task `name` (its model in the registry `models`: `version`, default `champion`, else
    `latest`), or the shipped default in `models/` when `models` is None."""
    task = get_task(name)
    if models is None:
        folder = DEFAULT_MODELS / task.name
        if not folder.exists():
            raise ModelFilesError(f"no default {task.name} model is shipped in {DEFAULT_MODELS}; train one "
                                  f"(farm train {task.name}) and pass --models")
        return predictor_from_folder(folder, task.name, source=f"shipped default {folder}")
    registry = models if isinstance(models, Registry) else open_registry(models, create=False)
    if version is None:
        chosen = registry.champion(task.model_name) or registry.latest(task.model_name)
        if chosen is None:
            raise RegistryError(f"model {task.model_name!r} has no version in the model registry {registry.label}; "
                                f"train one: farm train {task.name} --data DIR --models {registry.label}")
        version = chosen.version
    folder = _cached_download(registry, registry.version(task.model_name, version))
    return predictor_from_folder(folder, task.name, source=f"{registry.label} {task.model_name} v{version}")


def _cached_download(registry: Registry, found) -> Path:
    """The version's files in the local cache (a run's files never change, so one download serves every later
    load): $XDG_CACHE_HOME/treefarm/models/<registry digest>/NAME-vN-<run>, default under ~/.cache."""
    root = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "treefarm" / "models"
    name, version = found.name, found.version
    registry_key = hashlib.sha256(registry.uri.encode()).hexdigest()[:12]
    folder = root / registry_key / f"{name}-v{version}-{found.run_id[:12]}"
    if not (folder / _MANIFEST).exists():
        if folder.exists():  # an older, partial copy: downloads land whole, so this one predates that
            shutil.rmtree(folder)
        registry.download(name, version, folder)
    return folder


# ---------------------------------------------------------------------------------------------- retraining
@dataclass
class RetrainOutcome:
    """What a retrain did: the challenger's version, the champion it met, both scores, the decision and why."""

    task: str
    challenger_version: int
    champion_version: int | None
    promoted: bool
    reason: str
    challenger_metrics: dict
    champion_metrics: dict | None
    report: dict


def _score_folder(folder: Path, task: str, batches: Sequence[dict]) -> dict[str, float]:
    """Held-out metrics of the model files in `folder` on evaluation batches, through its torch weights."""
    import torch  # the torch networks: the predictor (ONNX Runtime) loads without them

    from .networks import TrainSettings, network_for

    manifest = json.loads((folder / _MANIFEST).read_text())
    codec = ParameterCodec.from_dict(json.loads((folder / "codec.json").read_text())) \
        if get_task(task).network == "sketchnet" else None
    network = network_for(task, TrainSettings.from_dict(manifest["settings"]), codec).build()
    network.load_state_dict(torch.load(folder / "weights.pt", map_location="cpu", weights_only=True))
    return network.metrics(batches)


def retrain(task: str, data: str | Sequence[str], registry: Registry, *, run_dir: str | Path,
            settings=None, workers: int = 1, gpus: int = 0, code_version: str = "unknown",
            progress: bool = False, report_dir: str | Path | None = None) -> RetrainOutcome:
    """Train a challenger and promote it only if it beats the champion on the champion's held-out split (see the
    module docstring). The report goes to `report_dir` (default: the run folder) as retrain-report.md/.json."""
    # torch's data, networks and training loop on Ray Train: the predictor (ONNX Runtime) loads without them
    from .data import Split, TaskDataset
    from .networks import TrainSettings
    from .training import evaluation_batches, train

    spec = get_task(task)
    name = spec.model_name
    champion = registry.champion(name)
    frozen, codec, warm, champion_folder, champion_settings = None, None, None, None, None
    if champion is not None:
        champion_folder = registry.download(name, champion.version)
        frozen = Split.from_json(json.dumps(registry.load_json(name, champion.version, "split")))
        if spec.network == "sketchnet":
            codec = ParameterCodec.from_dict(json.loads((champion_folder / "codec.json").read_text()))
        warm = champion_folder / "weights.pt"
        champion_settings = json.loads((champion_folder / _MANIFEST).read_text())["settings"]
    elif (DEFAULT_MODELS / spec.name / "weights.pt").exists():
        default = DEFAULT_MODELS / spec.name
        warm = default / "weights.pt"
        champion_settings = json.loads((default / _MANIFEST).read_text())["settings"]
        if spec.network == "sketchnet":
            codec = ParameterCodec.from_dict(json.loads((default / "codec.json").read_text()))
    if settings is None:
        settings = TrainSettings.from_dict(champion_settings) if champion_settings else TrainSettings()
    elif champion_settings is not None:
        # The warm start needs the same architecture: width and depth come from the champion.
        settings = TrainSettings.from_dict({**settings.to_dict(), "width": champion_settings["width"],
                                            "depth": champion_settings["depth"]})
    started = time.perf_counter()
    result = train(spec.name, data, settings=settings, run_dir=run_dir, workers=workers, gpus=gpus,
                   frozen_split=frozen, warm_start=warm, codec=codec, progress=progress)
    champion_metrics = None
    if champion_folder is not None:
        test = TaskDataset(result.data, result.split, "test")
        champion_metrics = _score_folder(champion_folder, spec.name, evaluation_batches(test, codec))
    network = result.network
    primary, baseline = network.primary, result.baseline_metrics
    if champion_metrics is None and primary in baseline and network.better(baseline, result.test_metrics):
        promoted = False
        reason = (f"the registry has no {name} champion yet, but the challenger's {primary} "
                  f"{result.test_metrics[primary]:.4g} is worse than its baseline's {baseline[primary]:.4g} "
                  f"({'higher' if network.higher_is_better else 'lower'} is better): registered, not made champion")
    elif champion_metrics is None:
        promoted, reason = True, f"the registry has no {name} champion yet: the first version becomes champion"
    elif network.better(result.test_metrics, champion_metrics):
        promoted = True
        reason = (f"the challenger's {network.primary} {result.test_metrics[network.primary]:.4g} beats the "
                  f"champion v{champion.version}'s {champion_metrics[network.primary]:.4g} on the champion's "
                  f"held-out split ({'higher' if network.higher_is_better else 'lower'} is better)")
    else:
        promoted = False
        reason = (f"the challenger's {network.primary} {result.test_metrics[network.primary]:.4g} does not beat "
                  f"the champion v{champion.version}'s {champion_metrics[network.primary]:.4g} on the champion's "
                  f"held-out split ({'higher' if network.higher_is_better else 'lower'} is better): the champion "
                  f"stays")
    report = {"task": spec.name, "model": name, "promoted": promoted, "reason": reason,
              "primary_metric": network.primary, "higher_is_better": network.higher_is_better,
              "champion_version": None if champion is None else champion.version,
              "challenger": {"test": result.test_metrics, "baseline": result.baseline_metrics,
                             "epochs": result.epochs, "steps": result.steps},
              "champion": None if champion_metrics is None else {"test": champion_metrics},
              "data": result.summary, "warm_start": None if warm is None else (f"champion v{champion.version}" if champion is not None else f"shipped default {warm.parent}"),
              "seconds": time.perf_counter() - started, "code_version": code_version}
    version = register_result(registry, result, code_version=code_version, promote=promoted,
                              extra_blobs={"retrain_report": report})
    report["challenger_version"] = version.version
    _write_report(Path(report_dir) if report_dir is not None else result.run_dir, report)
    return RetrainOutcome(spec.name, version.version, report["champion_version"], promoted, reason,
                          result.test_metrics, champion_metrics, report)


def _write_report(folder: Path, report: dict) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "retrain-report.json").write_text(json.dumps(report, indent=1, sort_keys=True, default=str))
    primary = report["primary_metric"]
    challenger = report["challenger"]["test"]
    champion = (report["champion"] or {}).get("test", {})
    baseline = report["challenger"]["baseline"]
    decision = "promoted" if report["promoted"] else \
        "champion kept" if report["champion_version"] is not None else "not made champion"
    lines = [f"# Retraining {report['task']}: {decision}", "", report["reason"] + ".", "",
             f"Challenger: version {report.get('challenger_version')}, "
             f"{counted(report['challenger']['epochs'], 'epoch')}, {counted(report['challenger']['steps'], 'step')}, "
             f"warm start {report['warm_start'] or 'none'}; "
             f"data: {counted(report['data']['trees']['train'], 'training tree')}, "
             f"{report['data']['trees']['test']} held out, {report['data']['rejected']} rejected by reviewers.", "",
             "| metric | challenger | champion | baseline |", "|---|---|---|---|"]
    for key in sorted(challenger):
        marker = " (decides)" if key == primary else ""
        lines.append(f"| {key}{marker} | {_cell(challenger, key)} | {_cell(champion, key)} | "
                     f"{_cell(baseline, key)} |")
    (folder / "retrain-report.md").write_text("\n".join(lines) + "\n")


def counted(number: int, noun: str) -> str:
    """'1 epoch', '2 epochs': a count with its noun in the number it takes."""
    return f"{number} {noun}{'' if number == 1 else 's'}"


def _cell(values: dict, key: str) -> str:
    return f"{values[key]:.4g}" if key in values and values[key] is not None else "-"
