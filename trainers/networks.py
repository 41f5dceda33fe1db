"""What each task's network needs from a training loop, behind one interface: build, step, predict, score, export.

`network_for(task, settings, codec)` gives a `TaskNetwork`: `SketchNetwork` (TreeSketchNet: image -> parameter
dictionary heads), `Pix2PixNetwork` (U-Net generator with a PatchGAN: sketch -> depth maps) or `SegmentNetwork`
(the tree mask U-Net: photo -> tree probabilities). The training loop
(`trainers.training`) and the predictor (`trainers.predictor`) see only this interface; the batches are dicts of
numpy arrays as the loaders give them (`input` (B, C, S, S) float32, then the task's targets).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import torch

from species.errors import TreefarmError

from . import pix2pix, segment, sketchnet
from .onnx_runtime import export_onnx
from .sketchnet_codec import ParameterCodec
from .tasks import Task, get_task

__all__ = ["SCHEDULES", "schedule_factor", "TrainSettings", "TaskNetwork", "SketchNetwork", "Pix2PixNetwork",
           "SegmentNetwork", "network_for", "SettingsError", "DEFAULT_SETTINGS"]


SCHEDULES = ("constant", "cosine")


def schedule_factor(schedule: str, step: int, total_steps: int) -> float:
    """The learning rate's multiplier at `step` (0-based) of `total_steps`: 1 (constant) or the cosine from 1 at
    the first step to 0 after the last."""
    if schedule == "constant":
        return 1.0
    return 0.5 * (1.0 + np.cos(np.pi * min(step, total_steps) / max(total_steps, 1)))


class SettingsError(TreefarmError):
    """A training setting out of its range (epochs, batch size, width, learning rate, ...)."""


@dataclass(frozen=True)
class TrainSettings:
    """One training run's settings (JSON-able; stored with the run and the model).

    width : TreeSketchNet's width multiplier (1.0 = B0) or the U-Net's base channels (16 by default: small
    enough for both networks to run per sketch on one core, benchmarks/bench_inference.py). depth : TreeSketchNet's
    depth multiplier. learning_rate : None = the network's default (TreeSketchNet 1e-3: the paper's 1e-5 over
    2,000 epochs does not fit a CPU budget; pix2pix 2e-4, beta1 0.5). time_budget_s : stop after this much
    training time, at the end of the batch that crosses it (the benchmark's fixed budget). schedule : the
    learning rate over the run's steps (epochs x batches per epoch): "constant" (the papers'), or "cosine"
    (from the rate down to 0 by the last step; a short run ends on small steps), set from the step count, so a
    resumed run continues the same curve.
    """

    epochs: int = 20
    batch_size: int = 16
    width: float | None = None
    depth: float = 1.0
    learning_rate: float | None = None
    seed: int = 0
    time_budget_s: float | None = None
    discriminator: str = "patch"
    schedule: str = "constant"

    def __post_init__(self) -> None:
        checks = [("epochs", self.epochs, 1, 100_000), ("batch_size", self.batch_size, 1, 4096),
                  ("seed", self.seed, 0, 2**31 - 1)]
        for name, value, low, high in checks:
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or not low <= value <= high:
                raise SettingsError(f"{name} = {value!r} is invalid: allowed an integer in [{low}, {high}]")
        for name, value in (("width", self.width), ("learning_rate", self.learning_rate),
                            ("time_budget_s", self.time_budget_s), ("depth", self.depth)):
            if value is not None and not (isinstance(value, (int, float)) and np.isfinite(value) and value > 0):
                raise SettingsError(f"{name} = {value!r} is invalid: allowed a positive number")
        if self.schedule not in SCHEDULES:
            raise SettingsError(f"schedule = {self.schedule!r} is invalid: allowed one of {', '.join(SCHEDULES)}")
        if self.discriminator not in pix2pix.DISCRIMINATORS:
            raise SettingsError(f"discriminator = {self.discriminator!r} is invalid: allowed one of "
                                f"{sorted(pix2pix.DISCRIMINATORS)}")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: Mapping) -> "TrainSettings":
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(data) - known)
        if unknown:
            raise SettingsError(f"training setting {unknown[0]!r} is unknown: allowed {', '.join(sorted(known))}")
        return cls(**dict(data))


DEFAULT_SETTINGS = {"sketchnet": {"width": 1.0, "learning_rate": 1e-3},
                    "pix2pix": {"width": 16, "learning_rate": pix2pix.LEARNING_RATE},
                    "segment": {"width": 8, "learning_rate": segment.LEARNING_RATE}}


@dataclass
class TaskNetwork:
    """The modules of one task's network and how to train, score and export them (see the module docstring)."""

    task: Task
    settings: TrainSettings
    modules: dict[str, torch.nn.Module] = field(default_factory=dict)
    # The generator dropout and stochastic depth draw from (its state goes into checkpoints, so a resumed run
    # draws what the uninterrupted one would have).
    noise: torch.Generator | None = None

    # What a model is judged by: `primary` in the held-out metrics, better when higher if `higher_is_better`.
    primary: str = ""
    higher_is_better: bool = True
    # The held-out metrics the training curves show (the rest go to metrics.csv only).
    curve_metrics: tuple[str, ...] = ()

    def width(self) -> float:
        return self.settings.width if self.settings.width is not None else DEFAULT_SETTINGS[self.family]["width"]

    def learning_rate(self) -> float:
        rate = self.settings.learning_rate
        return rate if rate is not None else DEFAULT_SETTINGS[self.family]["learning_rate"]

    @property
    def family(self) -> str:
        """The network family (`trainers.tasks.NETWORKS`) the task names."""
        return self.task.network

    def better(self, challenger: Mapping[str, float], champion: Mapping[str, float]) -> bool:
        """Whether `challenger`'s primary metric beats `champion`'s (strictly)."""
        a, b = float(challenger[self.primary]), float(champion[self.primary])
        return a > b if self.higher_is_better else a < b

    def state_dict(self) -> dict:
        return {name: module.state_dict() for name, module in self.modules.items()}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        missing = sorted(set(self.modules) - set(state))
        if missing:
            raise SettingsError(f"the weights hold no {missing[0]!r} network: they hold {', '.join(sorted(state))}")
        for name, module in self.modules.items():
            module.load_state_dict(state[name])

    # Subclasses: build(), optimizers(), train_step(), predict(), metrics(), baseline_metrics(), export().


class SketchNetwork(TaskNetwork):
    """TreeSketchNet: a sketch (1 channel) to the codec's parameter heads and the species."""

    def __init__(self, task: Task, settings: TrainSettings, codec: ParameterCodec):
        super().__init__(task, settings, primary=task.primary_metric, higher_is_better=task.higher_is_better,
                         curve_metrics=("score_overall", "accuracy_species", "accuracy_categorical"))
        self.codec = codec

    def build(self) -> "SketchNetwork":
        torch.manual_seed(self.settings.seed)  # the backbone's initialisers draw from torch's default generator
        self.modules = {"model": sketchnet.TreeSketchNet(self.codec.head_sizes, self.codec.n_species,
                                                         in_channels=1, width=self.width(),
                                                         depth=self.settings.depth)}
        self.noise = torch.Generator().manual_seed(self.settings.seed + 1)
        self.modules["model"].set_noise_generator(self.noise)
        return self

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"model": torch.optim.Adam(self.modules["model"].parameters(), lr=self.learning_rate())}

    def targets(self, batch: Mapping[str, np.ndarray]) -> dict[str, torch.Tensor]:
        return {key: torch.as_tensor(np.asarray(value)) for key, value in batch.items()
                if key not in ("input", "index")}

    def train_step(self, optimizers, batch: Mapping[str, np.ndarray]) -> dict[str, float]:
        model = self.modules["model"]
        model.train()
        outputs = model(torch.as_tensor(batch["input"]))
        loss, _ = sketchnet.sketchnet_loss(outputs, self.targets(batch))
        optimizers["model"].zero_grad()
        loss.backward()
        optimizers["model"].step()
        return {"loss": float(loss.detach())}

    @torch.no_grad()
    def predict(self, inputs: np.ndarray) -> dict[str, torch.Tensor]:
        model = self.modules["model"]
        model.eval()
        return model(torch.tensor(np.asarray(inputs)))  # a copy: Ray's batches are read-only

    def metrics(self, batches: Sequence[Mapping[str, np.ndarray]]) -> dict[str, float]:
        outputs = [self.predict(b["input"]) for b in batches]
        joined = {key: torch.cat([o[key] for o in outputs]) for key in outputs[0]}
        return sketchnet.sketchnet_metrics(joined, _joined_targets(self, batches))

    def baseline_metrics(self, batches: Sequence[Mapping[str, np.ndarray]]) -> dict[str, float]:
        """The mean-parameter baseline (training means, most frequent classes) on the same batches."""
        targets = _joined_targets(self, batches)
        count = len(next(iter(targets.values())))
        outputs = {key: torch.as_tensor(value) for key, value in self.codec.baseline_outputs(count).items()}
        return sketchnet.sketchnet_metrics(outputs, targets)

    def export(self, folder: Path) -> dict[str, Path]:
        """ONNX (`sketchnet.onnx`), torch weights (`weights.pt`) and the codec (`codec.json`)."""
        folder = Path(folder)
        onnx = sketchnet.export_onnx(self.modules["model"], folder / "sketchnet.onnx",
                                     image_size=self.task.input_size)
        weights = folder / "weights.pt"
        torch.save(self.state_dict(), weights)
        codec = folder / "codec.json"
        codec.write_text(json.dumps(self.codec.to_dict(), indent=1, sort_keys=True))
        return {"sketchnet.onnx": onnx, "weights.pt": weights, "codec.json": codec}


def _joined_targets(network: SketchNetwork, batches) -> dict[str, torch.Tensor]:
    targets = [network.targets(b) for b in batches]
    return {key: torch.cat([t[key] for t in targets]) for key in targets[0]}


class Pix2PixNetwork(TaskNetwork):
    """A pix2pix U-Net with its discriminator: sketch to depth maps (silhouette: front, gap, mask; trunk)."""

    def __init__(self, task: Task, settings: TrainSettings):
        super().__init__(task, settings, primary=task.primary_metric, higher_is_better=task.higher_is_better,
                         curve_metrics=("depth_error",))

    def build(self) -> "Pix2PixNetwork":
        generator = torch.Generator().manual_seed(self.settings.seed)
        width = int(round(self.width()))
        # One generator initialises both networks, then draws the U-Net's dropout masks.
        self.modules = {"generator": pix2pix.task_generator(self.task, width, generator=generator),
                        "discriminator": pix2pix.task_discriminator(self.task, self.settings.discriminator, width,
                                                                    self.task.input_size, generator)}
        self.noise = generator
        return self

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        rate = self.learning_rate()
        return {name: pix2pix.make_optimizer(module, lr=rate) for name, module in self.modules.items()}

    def train_step(self, optimizers, batch: Mapping[str, np.ndarray]) -> dict[str, float]:
        for module in self.modules.values():
            module.train()
        losses = pix2pix.pix2pix_step(self.modules["generator"], self.modules["discriminator"],
                                      optimizers["generator"], optimizers["discriminator"],
                                      tuple(torch.as_tensor(batch[k]) for k in ("input", "target", "mask")),
                                      dense_channels=self.task.dense_channels)
        return {"loss": losses["loss_g"], **losses}

    @torch.no_grad()
    def predict(self, inputs: np.ndarray) -> torch.Tensor:
        generator = self.modules["generator"]
        generator.eval()
        return generator(torch.tensor(np.asarray(inputs)))  # a copy: Ray's batches are read-only

    def metrics(self, batches: Sequence[Mapping[str, np.ndarray]]) -> dict[str, float]:
        predicted = torch.cat([self.predict(b["input"]) for b in batches])
        target, mask = _joined(batches, "target"), _joined(batches, "mask")
        return {"depth_error": pix2pix.masked_depth_error(predicted, target, mask, self.task.depth_channels)}

    def baseline_metrics(self, batches: Sequence[Mapping[str, np.ndarray]],
                         mean_depth: np.ndarray | None = None) -> dict[str, float]:
        """The mean-depth baseline: every foreground pixel of each channel predicted as the mean of that
        channel over the foreground of `batches` (pass the training set's as `mean_depth`)."""
        target, mask = _joined(batches, "target"), _joined(batches, "mask")
        if mean_depth is None:
            mean_depth = self.mean_depth(batches)
        predicted = torch.as_tensor(mean_depth, dtype=torch.float32)[None, :, None, None].expand_as(target)
        return {"depth_error": pix2pix.masked_depth_error(predicted, target, mask, self.task.depth_channels)}

    @staticmethod
    def mean_depth(batches: Sequence[Mapping[str, np.ndarray]]) -> np.ndarray:
        """(C,) mean of each target channel over the foreground mask of `batches`."""
        target, mask = _joined(batches, "target").numpy(), _joined(batches, "mask").numpy()
        weight = np.broadcast_to(mask, target.shape)
        return (target * weight).sum(axis=(0, 2, 3)) / np.maximum(weight.sum(axis=(0, 2, 3)), 1.0)

    def export(self, folder: Path) -> dict[str, Path]:
        """ONNX of the generator (`TASK.onnx`) and the torch weights of both networks (`weights.pt`)."""
        folder = Path(folder)
        in_channels, _ = pix2pix.task_channels(self.task)
        example = torch.zeros(1, in_channels, self.task.input_size, self.task.input_size)
        name = f"{self.task.name}.onnx"
        onnx = export_onnx(self.modules["generator"], example, folder / name, ["sketch"], ["depth"])
        weights = folder / "weights.pt"
        torch.save(self.state_dict(), weights)
        return {name: onnx, "weights.pt": weights}


class SegmentNetwork(TaskNetwork):
    """The tree mask U-Net (`trainers.segment.MaskUNet`): a photo (3 channels) to its tree probabilities."""

    def __init__(self, task: Task, settings: TrainSettings):
        super().__init__(task, settings, primary=task.primary_metric, higher_is_better=task.higher_is_better,
                         curve_metrics=("mask_iou",))

    def build(self) -> "SegmentNetwork":
        self.noise = torch.Generator().manual_seed(self.settings.seed)
        self.modules = {"model": segment.MaskUNet(3, int(round(self.width())), generator=self.noise)}
        return self

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"model": torch.optim.Adam(self.modules["model"].parameters(), lr=self.learning_rate())}

    def train_step(self, optimizers, batch: Mapping[str, np.ndarray]) -> dict[str, float]:
        model = self.modules["model"]
        model.train()
        loss = segment.mask_loss(model(torch.as_tensor(batch["input"])), torch.as_tensor(batch["target"]))
        optimizers["model"].zero_grad()
        loss.backward()
        optimizers["model"].step()
        return {"loss": float(loss.detach())}

    @torch.no_grad()
    def predict(self, inputs: np.ndarray) -> torch.Tensor:
        model = self.modules["model"]
        model.eval()
        return model.probabilities(torch.tensor(np.asarray(inputs)))  # a copy: Ray's batches are read-only

    def metrics(self, batches: Sequence[Mapping[str, np.ndarray]]) -> dict[str, float]:
        predicted = torch.cat([self.predict(b["input"]) for b in batches]).numpy()
        return {"mask_iou": segment.mask_iou(predicted, _joined(batches, "target").numpy())}

    def baseline_metrics(self, batches: Sequence[Mapping[str, np.ndarray]],
                         mean_depth: np.ndarray | None = None) -> dict[str, float]:
        """The trivial baseline: every pixel the tree's when the training views' tree share (`mean_depth`, the
        name the loop passes it by) is half or more, else none."""
        target = _joined(batches, "target").numpy()
        share = float(self.mean_depth(batches)[0] if mean_depth is None else mean_depth[0])
        return {"mask_iou": segment.mask_iou(np.full(target.shape, share >= 0.5, np.float32), target)}

    @staticmethod
    def mean_depth(batches: Sequence[Mapping[str, np.ndarray]]) -> np.ndarray:
        """(1,) the share of tree pixels in `batches`."""
        return np.array([float(_joined(batches, "target").float().mean())])

    def export(self, folder: Path) -> dict[str, Path]:
        """ONNX of the network with its sigmoid (`TASK.onnx`, any height and width that are multiples of 8) and
        the torch weights (`weights.pt`)."""
        folder = Path(folder)
        example = torch.zeros(1, 3, self.task.input_size, self.task.input_size)
        name = f"{self.task.name}.onnx"
        onnx = export_onnx(segment.with_sigmoid(self.modules["model"]), example, folder / name, ["photo"], ["mask"],
                           spatial_axes=True)
        weights = folder / "weights.pt"
        torch.save(self.state_dict(), weights)
        return {name: onnx, "weights.pt": weights}


def _joined(batches, key: str) -> torch.Tensor:
    return torch.cat([torch.as_tensor(np.asarray(b[key])) for b in batches])


def network_for(task: str | Task, settings: TrainSettings, codec: ParameterCodec | None = None) -> TaskNetwork:
    """The (unbuilt) network of `task` (its family, `Task.network`); TreeSketchNet needs the parameter codec."""
    task = get_task(task)
    if task.network == "sketchnet":
        if codec is None:
            raise SettingsError("TreeSketchNet needs its parameter codec (ParameterCodec.fit on the training "
                                "dictionaries)")
        return SketchNetwork(task, settings, codec)
    if task.network == "segment":
        return SegmentNetwork(task, settings)
    return Pix2PixNetwork(task, settings)
