"""The tree mask network (issue 51): a small U-Net that marks a photo's tree pixels, its loss, score and records.

In: photos as (B, 3, H, W) float32 RGB in [0, 1] (H and W multiples of `MaskUNet.size_multiple`; any size, the
network is fully convolutional); out: (B, 1, H, W) tree probabilities. The task (`trainers.tasks.TASKS`,
network "segment") reads the "photo" render output and learns "photo_mask" (the renderer's own tree pixels).

Choices: two 3x3 convolutions with batch norm and ReLU per level, max pooling down, bilinear upsampling and a
skip concatenation up (no transposed convolutions, so no checkerboard on thin branches), widths w, 2w, 4w, 8w;
the loss is binary cross-entropy plus a soft Dice term (trees are a small share of many views, where cross-entropy
alone favours the background); the score is the pooled pixel IoU at 0.5. The augmentation of a training photo
(`augment_photo`) flips it, jitters its geometry and its colours, so the renders' exact palette is not learnt.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import cv2
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from species.errors import TreefarmError

from .tasks import Task

__all__ = ["SegmentError", "MaskUNet", "mask_loss", "mask_iou", "targets_from_views", "augment_photo",
           "LEARNING_RATE", "THRESHOLD"]

LEARNING_RATE = 3e-3
THRESHOLD = 0.5           # a pixel is the tree's at this probability or above
_LEVELS = 4               # resolution levels: three poolings, so sizes are multiples of 8
_GEOMETRY = {"rotation_deg": 8.0, "scale": (0.7, 1.2), "shift": 0.1}
_COLOUR = {"brightness": 0.25, "contrast": 0.3, "saturation": 0.4, "hue_deg": 12.0}


class SegmentError(TreefarmError):
    """A mask network or batch asked for with a shape or value it does not allow."""


def _block(c_in: int, c_out: int) -> nn.Sequential:
    return nn.Sequential(nn.Conv2d(c_in, c_out, 3, padding=1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU(),
                         nn.Conv2d(c_out, c_out, 3, padding=1, bias=False), nn.BatchNorm2d(c_out), nn.ReLU())


class MaskUNet(nn.Module):
    """U-Net of `_LEVELS` levels: width, 2 width, ... channels; forward(x (B, 3, H, W)) -> logits (B, 1, H, W).

    `probabilities(x)` gives the sigmoid; the exported model (`export`) ends in it. generator : torch.Generator
    for the initial weights (None: seed 0, so two networks built alike are alike)."""

    def __init__(self, in_channels: int = 3, width: int = 8, generator: torch.Generator | None = None):
        super().__init__()
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 1:
            raise SegmentError(f"width = {width!r} is invalid: allowed an integer >= 1")
        self.in_channels, self.width = int(in_channels), int(width)
        channels = [self.width * 2 ** i for i in range(_LEVELS)]
        self.down = nn.ModuleList([_block(self.in_channels, channels[0])] +
                                  [_block(channels[i - 1], channels[i]) for i in range(1, _LEVELS)])
        self.up = nn.ModuleList([_block(channels[i] + channels[i - 1], channels[i - 1])
                                 for i in range(_LEVELS - 1, 0, -1)])
        self.head = nn.Conv2d(channels[0], 1, 1)
        generator = torch.Generator().manual_seed(0) if generator is None else generator
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                fan_in = m.in_channels * m.kernel_size[0] * m.kernel_size[1]
                nn.init.normal_(m.weight, 0.0, float(np.sqrt(2.0 / fan_in)), generator=generator)
                if m.bias is not None:
                    nn.init.zeros_(m.bias)

    @property
    def size_multiple(self) -> int:
        return 2 ** (_LEVELS - 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not torch.jit.is_tracing() and (x.ndim != 4 or x.shape[1] != self.in_channels
                                           or x.shape[2] % self.size_multiple or x.shape[3] % self.size_multiple):
            raise SegmentError(f"MaskUNet input has shape {tuple(x.shape)}: allowed (B, {self.in_channels}, H, W) "
                               f"with H and W multiples of {self.size_multiple}")
        skips = []
        for i, block in enumerate(self.down):
            x = block(x if i == 0 else F.max_pool2d(x, 2))
            skips.append(x)
        for block, skip in zip(self.up, reversed(skips[:-1])):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = block(torch.cat([x, skip], dim=1))
        return self.head(x)

    def probabilities(self, x: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self(x))


class _Probabilities(nn.Module):
    """The network ending in its sigmoid: what the ONNX file holds."""

    def __init__(self, network: MaskUNet):
        super().__init__()
        self.network = network

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.network(x))


def with_sigmoid(network: MaskUNet) -> nn.Module:
    """`network` ending in its sigmoid (probabilities), for export."""
    return _Probabilities(network)


def mask_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy plus soft Dice (1 - 2|PT| / (|P| + |T|), pooled over the batch); scalar tensor."""
    bce = F.binary_cross_entropy_with_logits(logits, target)
    p = torch.sigmoid(logits)
    dice = 1.0 - (2.0 * (p * target).sum() + 1.0) / (p.sum() + target.sum() + 1.0)
    return bce + dice


def mask_iou(probabilities, target) -> float:
    """Pixel IoU of probabilities >= THRESHOLD against target > 0.5, pooled over every image (1 when both empty)."""
    p = np.asarray(probabilities) >= THRESHOLD
    t = np.asarray(target) > 0.5
    union = int((p | t).sum())
    return float((p & t).sum() / union) if union else 1.0


def targets_from_views(task: Task, item: Mapping) -> tuple[None, np.ndarray, np.ndarray]:
    """(None, target (1, H, W) float32 0/1, loss mask (1, H, W) of ones) from a view's cut outputs (C, H, W):
    the tree's pixels of the task's target output (label > 0); every pixel counts in the loss."""
    name = task.targets[0]
    if name not in item:
        raise SegmentError(f"the {task.name} task needs output {name!r}, which this view lacks: make the data "
                           f"with trainers/specs/{task.spec_name}.yaml")
    labels = np.asarray(item[name])
    target = (labels.reshape((1,) + labels.shape[-2:]) > 0).astype(np.float32)
    return None, target, np.ones_like(target)


def _colour_jitter(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(3, S, S) RGB in [0, 1] with brightness, contrast, saturation and hue jittered."""
    hwc = np.ascontiguousarray(np.moveaxis(image, 0, 2))
    hsv = cv2.cvtColor(hwc, cv2.COLOR_RGB2HSV)                # float32: H in degrees, S and V in [0, 1]
    hsv[..., 0] = (hsv[..., 0] + rng.uniform(-1, 1) * _COLOUR["hue_deg"]) % 360.0
    hsv[..., 1] *= 1.0 + rng.uniform(-1, 1) * _COLOUR["saturation"]
    out = cv2.cvtColor(np.clip(hsv, 0, [360, 1, 1]).astype(np.float32), cv2.COLOR_HSV2RGB)
    mean = out.mean()
    out = (out - mean) * (1.0 + rng.uniform(-1, 1) * _COLOUR["contrast"]) + mean
    out = out * (1.0 + rng.uniform(-1, 1) * _COLOUR["brightness"])
    return np.moveaxis(np.clip(out, 0.0, 1.0), 2, 0)


def augment_photo(image: np.ndarray, rng: np.random.Generator, targets: Sequence[tuple[np.ndarray, Sequence[float]]]
                  = ()) -> tuple[np.ndarray, list[np.ndarray]]:
    """One training draw for a photo (3, S, S) float32 and its targets (C, S, S) (with a fill per channel):
    a mirror (p = 0.5), one affine (rotation, scale, shift: smaller trees than the renders frame, off centre)
    applied to all alike, the photo's edges filled by reflection (a backdrop, not a border); then colour jitter
    on the photo only. Returns (photo, targets)."""
    size = image.shape[-1]
    flip = rng.random() < 0.5
    angle = rng.uniform(-1, 1) * _GEOMETRY["rotation_deg"]
    scale = rng.uniform(*_GEOMETRY["scale"])
    shift = rng.uniform(-1, 1, 2) * _GEOMETRY["shift"] * size
    matrix = cv2.getRotationMatrix2D(((size - 1) / 2.0, (size - 1) / 2.0), angle, scale)
    matrix[:, 2] += shift

    def warp(array: np.ndarray, interpolation: int, border: int, fill: Sequence[float]) -> np.ndarray:
        array = array[..., ::-1] if flip else array
        hwc = np.ascontiguousarray(np.moveaxis(array, 0, 2), np.float32)
        value = tuple(float(v) for v in fill) + (0.0,) * (4 - len(fill))
        out = cv2.warpAffine(hwc, matrix, (size, size), flags=interpolation, borderMode=border, borderValue=value)
        return np.ascontiguousarray(np.moveaxis(out.reshape(size, size, -1), 2, 0), np.float32)

    photo = warp(image, cv2.INTER_LINEAR, cv2.BORDER_REFLECT_101, (0.0,) * image.shape[0])
    # The mask follows the photo's reflected edges too, so a mirrored tree piece is labelled where it shows.
    warped = [warp(t, cv2.INTER_NEAREST, cv2.BORDER_REFLECT_101, fill) for t, fill in targets]
    return _colour_jitter(photo, rng).astype(np.float32), warped
