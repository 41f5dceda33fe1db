"""TreeSketchNet: a sketch to a Weber-Penn dictionary. The network (an EfficientNet-style backbone in plain torch,
the codec's regression and classification heads, a species head), its loss, its metrics and ONNX export.

In: (B, C, H, W) float sketches as `trainers.preprocess` makes them. Out: a dict of head outputs that
`ParameterCodec.decode_batch` turns into dictionaries; `sketchnet_loss` and `sketchnet_metrics` compare them with
`ParameterCodec.encode_batch` targets; `grown_tree_errors` grows predicted and true dictionaries and compares them.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

import species
from species.errors import TreefarmError

from .sketchnet_codec import REGRESSION_HEADS, SPECIES_HEAD

__all__ = ["TreeSketchNet", "MBConvSpec", "EFFICIENTNET_B0", "sketchnet_loss", "sketchnet_metrics",
           "grown_tree_errors", "export_onnx", "ONNX_INPUT", "SketchNetError"]

ONNX_INPUT = "sketch"


class SketchNetError(TreefarmError):
    """A network setting or a tensor TreeSketchNet cannot take."""


@dataclass(frozen=True)
class MBConvSpec:
    """One stage of MBConv blocks: expansion ratio, kernel size, stride of its first block, output channels and
    repeats (at width and depth 1)."""

    expand: int
    kernel: int
    stride: int
    channels: int
    repeats: int


# EfficientNet-B0 (Tan & Le 2019, table 1): stem 32 channels, these seven stages, a 1280-channel head.
EFFICIENTNET_B0 = (MBConvSpec(1, 3, 1, 16, 1), MBConvSpec(6, 3, 2, 24, 2), MBConvSpec(6, 5, 2, 40, 2),
                   MBConvSpec(6, 3, 2, 80, 3), MBConvSpec(6, 5, 1, 112, 3), MBConvSpec(6, 5, 2, 192, 4),
                   MBConvSpec(6, 3, 1, 320, 1))
STEM_CHANNELS, HEAD_CHANNELS = 32, 1280


def _round_channels(channels: float, divisor: int = 8) -> int:
    """EfficientNet's width rounding: to a multiple of `divisor`, never below 90 % of the request."""
    rounded = max(divisor, int(channels + divisor / 2) // divisor * divisor)
    return rounded + divisor if rounded < 0.9 * channels else rounded


def _conv_bn(cin: int, cout: int, kernel: int, stride: int = 1, groups: int = 1, act: bool = True) -> nn.Sequential:
    layers = [nn.Conv2d(cin, cout, kernel, stride, kernel // 2, groups=groups, bias=False), nn.BatchNorm2d(cout)]
    return nn.Sequential(*layers, nn.SiLU()) if act else nn.Sequential(*layers)


class SqueezeExcite(nn.Module):
    """Channel gates from the globally pooled features (squeeze to `squeezed` channels, excite back)."""

    def __init__(self, channels: int, squeezed: int):
        super().__init__()
        self.reduce = nn.Conv2d(channels, squeezed, 1)
        self.expand = nn.Conv2d(squeezed, channels, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        gate = x.mean(dim=(2, 3), keepdim=True)
        return x * torch.sigmoid(self.expand(F.silu(self.reduce(gate))))


class _Noise:
    """Where the network's training noise (stochastic depth, dropout) comes from: a seeded torch.Generator set
    with `TreeSketchNet.set_noise_generator`, or torch's default generator when none is set."""

    def __init__(self):
        self.generator: torch.Generator | None = None

    def uniform(self, shape: tuple, like: torch.Tensor) -> torch.Tensor:
        return torch.rand(shape, generator=self.generator, device=like.device, dtype=like.dtype)


class MBConv(nn.Module):
    """Inverted residual block: 1x1 expansion, depthwise k x k, squeeze-excitation (a quarter of the input
    channels), 1x1 projection; a residual with stochastic depth where the shape is kept."""

    def __init__(self, cin: int, cout: int, expand: int, kernel: int, stride: int, drop_path: float,
                 noise: _Noise):
        super().__init__()
        hidden = cin * expand
        self.expand = _conv_bn(cin, hidden, 1) if expand != 1 else nn.Identity()
        self.depthwise = _conv_bn(hidden, hidden, kernel, stride, groups=hidden)
        self.excite = SqueezeExcite(hidden, max(1, cin // 4))
        self.project = _conv_bn(hidden, cout, 1, act=False)
        self.residual = stride == 1 and cin == cout
        self.drop_path = drop_path
        self.noise = noise

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.project(self.excite(self.depthwise(self.expand(x))))
        if not self.residual:
            return out
        if self.training and self.drop_path > 0:
            keep = 1.0 - self.drop_path
            mask = self.noise.uniform((x.shape[0], 1, 1, 1), x) < keep
            out = out * mask.to(out.dtype) / keep
        return x + out


class TreeSketchNet(nn.Module):
    """EfficientNet-style backbone (B0 at width = depth = 1), global average pooling, dropout, and one linear
    head per output: the codec's regression heads ((B, values), normalised), classification heads and the species
    head ((B, classes) logits). Outputs come in `output_names` order, the ONNX file's too.

    head_sizes  : output name -> width (`ParameterCodec.head_sizes`).
    n_species   : width of the species head (`ParameterCodec.n_species`).
    in_channels : 1 for greyscale sketches (`sketch_tsn`), 3 for colour.
    width, depth: EfficientNet's channel and repeat multipliers.
    dropout     : before the heads (the paper's 0.2).
    drop_path   : stochastic depth of the last block (linearly less toward the stem); EfficientNet's 0.2.
    """

    def __init__(self, head_sizes: Mapping[str, int], n_species: int, in_channels: int = 1, width: float = 1.0,
                 depth: float = 1.0, dropout: float = 0.2, drop_path: float = 0.2):
        super().__init__()
        _check_settings(head_sizes, n_species, in_channels, width, depth, dropout, drop_path)
        self.config = {"head_sizes": dict(head_sizes), "n_species": int(n_species), "in_channels": int(in_channels),
                       "width": float(width), "depth": float(depth), "dropout": float(dropout),
                       "drop_path": float(drop_path)}
        self.noise = _Noise()
        channels = _round_channels(STEM_CHANNELS * width)
        self.stem = _conv_bn(in_channels, channels, 3, stride=2)
        repeats = [math.ceil(stage.repeats * depth) for stage in EFFICIENTNET_B0]
        blocks, index, total = [], 0, sum(repeats)
        for stage, count in zip(EFFICIENTNET_B0, repeats):
            cout = _round_channels(stage.channels * width)
            for i in range(count):
                blocks.append(MBConv(channels, cout, stage.expand, stage.kernel, stage.stride if i == 0 else 1,
                                     drop_path * index / total, self.noise))
                channels, index = cout, index + 1
        self.blocks = nn.Sequential(*blocks)
        features = _round_channels(HEAD_CHANNELS * width)
        self.head_conv = _conv_bn(channels, features, 1)
        self.dropout = dropout
        self.heads = nn.ModuleDict({name: nn.Linear(features, size)
                                    for name, size in self.config["head_sizes"].items()})
        self.heads[SPECIES_HEAD] = nn.Linear(features, n_species)
        self._initialise()

    @property
    def output_names(self) -> list[str]:
        return list(self.heads)

    def set_noise_generator(self, generator: torch.Generator | None) -> None:
        """Draw stochastic depth and dropout from `generator` (on the model's device), or torch's default one."""
        self.noise.generator = generator

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """(B, features) pooled backbone features."""
        return self.head_conv(self.blocks(self.stem(x))).mean(dim=(2, 3))

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        if not torch.jit.is_tracing() and (x.dim() != 4 or x.shape[1] != self.config["in_channels"]):
            raise SketchNetError(f"TreeSketchNet takes (batch, {self.config['in_channels']}, height, width) images; "
                                 f"got shape {tuple(x.shape)}")
        pooled = self.features(x)
        if self.training and self.dropout > 0:
            keep = 1.0 - self.dropout
            pooled = pooled * (self.noise.uniform(pooled.shape, pooled) < keep).to(pooled.dtype) / keep
        return {name: head(pooled) for name, head in self.heads.items()}

    def _initialise(self) -> None:
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, mode="fan_out")
                if module.bias is not None:
                    nn.init.zeros_(module.bias)


def _check_settings(head_sizes, n_species, in_channels, width, depth, dropout, drop_path) -> None:
    if not head_sizes or any(not isinstance(v, int) or v < 1 for v in head_sizes.values()):
        raise SketchNetError(f"head_sizes must map output names to positive widths; got {dict(head_sizes)}")
    if SPECIES_HEAD in head_sizes:
        raise SketchNetError(f"head_sizes must not hold {SPECIES_HEAD!r}: its width is n_species")
    checks = [("n_species", n_species, isinstance(n_species, int) and n_species >= 1, "a positive integer"),
              ("in_channels", in_channels, in_channels in (1, 3), "1 (greyscale) or 3 (colour)"),
              ("width", width, 0 < width <= 8, "a multiplier in (0, 8]"),
              ("depth", depth, 0 < depth <= 8, "a multiplier in (0, 8]"),
              ("dropout", dropout, 0 <= dropout < 1, "a probability in [0, 1)"),
              ("drop_path", drop_path, 0 <= drop_path < 1, "a probability in [0, 1)")]
    for name, value, ok, allowed in checks:
        if not ok:
            raise SketchNetError(f"TreeSketchNet {name} = {value!r} is invalid: allowed {allowed}")


# ---------------------------------------------------------------------------------------------------- loss
def _head_kind(name: str) -> str:
    if name in REGRESSION_HEADS:
        return "regression"
    return "species" if name == SPECIES_HEAD else "class"


def _masked_squares(output: torch.Tensor, target: torch.Tensor,
                    mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Sum of squared errors over the mask, and the mask's count; a masked-out value (NaN included) adds 0."""
    error = torch.where(mask > 0, output - target, torch.zeros_like(output))
    return (error * error * mask).sum(), mask.sum()


def sketchnet_loss(outputs: Mapping[str, torch.Tensor],
                   targets: Mapping[str, torch.Tensor]) -> tuple[torch.Tensor, dict[str, float]]:
    """The training loss and its parts (floats, per head). Loss = mean over the regression heads of each head's
    MSE over its mask (unused levels and absent draws add nothing) + mean over the classification heads of their
    cross entropy + the species head's cross entropy (samples without a species, label -1, left out)."""
    parts: dict[str, torch.Tensor] = {}
    for name, output in outputs.items():
        kind = _head_kind(name)
        if kind == "regression":
            squares, count = _masked_squares(output, targets[name], targets[f"{name}_mask"])
            parts[name] = squares / count.clamp(min=1.0)
        else:
            labels = targets[name]
            known = labels >= 0
            loss = F.cross_entropy(output[known], labels[known]) if bool(known.any()) else output.sum() * 0.0
            parts[name] = loss
    regression = [parts[n] for n in parts if _head_kind(n) == "regression"]
    classes = [parts[n] for n in parts if _head_kind(n) == "class"]
    loss = torch.stack(regression).mean()
    if classes:
        loss = loss + torch.stack(classes).mean()
    if SPECIES_HEAD in parts:
        loss = loss + parts[SPECIES_HEAD]
    return loss, {name: float(value.detach()) for name, value in parts.items()}


# ---------------------------------------------------------------------------------------------------- metrics
@torch.no_grad()
def sketchnet_metrics(outputs: Mapping[str, torch.Tensor], targets: Mapping[str, torch.Tensor]) -> dict[str, float]:
    """The paper's score, (1 - RMSE) x 100 on normalised values over the mask, per regression head
    (`score_HEAD`) and over all of them (`score_overall`); accuracy per classification head (`accuracy_KEY`),
    their mean (`accuracy_categorical`) and the species accuracy (`accuracy_species`, over labelled samples)."""
    metrics: dict[str, float] = {}
    total_squares, total_count = 0.0, 0.0
    accuracies = []
    for name, output in outputs.items():
        kind = _head_kind(name)
        if kind == "regression":
            squares, count = _masked_squares(output.float(), targets[name], targets[f"{name}_mask"])
            total_squares, total_count = total_squares + float(squares), total_count + float(count)
            metrics[f"score_{name}"] = 100.0 * (1.0 - math.sqrt(float(squares) / max(float(count), 1.0)))
            continue
        labels = targets[name]
        known = labels >= 0
        correct = (output.argmax(dim=1) == labels)[known].float()
        accuracy = float(correct.mean()) if len(correct) else float("nan")
        if kind == "species":
            metrics["accuracy_species"] = accuracy
        else:
            metrics[f"accuracy_{name.removeprefix('class_')}"] = accuracy
            accuracies.append(accuracy)
    metrics["score_overall"] = 100.0 * (1.0 - math.sqrt(total_squares / max(total_count, 1.0)))
    if accuracies:
        metrics["accuracy_categorical"] = float(np.mean(accuracies))
    return metrics


def height_crown_row(predicted: "species.Skeleton", true: "species.Skeleton") -> dict[str, float]:
    """Height and crown radius (metres) of a predicted and a true skeleton and their relative errors
    |pred - true| / true: keys `height`, `true_height`, `height_rel_error`, and the same for `crown_radius`."""
    row = {}
    for measure in ("height", "crown_radius"):
        value, reference = float(getattr(predicted, measure)), float(getattr(true, measure))
        row[measure], row[f"true_{measure}"] = value, reference
        row[f"{measure}_rel_error"] = abs(value - reference) / max(reference, 1e-9)
    return row


def grown_tree_errors(predicted: Sequence[dict], true: Sequence[dict], seed: int = 0) -> dict:
    """Grow each predicted and true dictionary (`species.grow`, the same fixed seed for both) and compare
    height and crown radius (metres, `Skeleton.height` / `.crown_radius`): relative errors |pred - true| / true,
    their means over the trees (`height_rel_error`, `crown_radius_rel_error`) and per tree (`trees`)."""
    if len(predicted) != len(true) or len(true) == 0:
        raise SketchNetError(f"grown_tree_errors needs as many predicted as true dictionaries (at least one); got "
                             f"{len(predicted)} and {len(true)}")
    trees = [height_crown_row(*(species.grow(d, np.random.default_rng(seed)) for d in (guess, truth)))
             for guess, truth in zip(predicted, true)]
    return {"height_rel_error": float(np.mean([t["height_rel_error"] for t in trees])),
            "crown_radius_rel_error": float(np.mean([t["crown_radius_rel_error"] for t in trees])),
            "n": len(trees), "trees": trees}


# ---------------------------------------------------------------------------------------------------- ONNX
def export_onnx(model: TreeSketchNet, path: str | Path, image_size: int = 224, opset: int = 17) -> Path:
    """Write `model` (in eval mode) as ONNX: input `sketch` (batch, in_channels, H, W) float32 with a dynamic
    batch axis, one output per head named as `model.output_names`. Returns the path."""
    path = Path(path)
    was_training = model.training
    model.eval()
    example = torch.zeros(1, model.config["in_channels"], image_size, image_size)
    dynamic = {ONNX_INPUT: {0: "batch"}, **{name: {0: "batch"} for name in model.output_names}}
    try:
        with warnings.catch_warnings():  # the TorchScript exporter is the one we ask for; its notice is noise
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(model, (example,), str(path), input_names=[ONNX_INPUT],
                              output_names=model.output_names, dynamic_axes=dynamic, opset_version=opset,
                              dynamo=False)
    finally:
        model.train(was_training)
    return path
