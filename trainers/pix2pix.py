"""pix2pix for seed 000's two sketch-to-depth cGANs: U-Net generator, input-conditioned discriminators, losses.

In: sketch tensors (B, C, H, W) float32 in [0, 1]; out: depth maps (B, C, H, W) in [0, 1], losses, one train step.
The tasks (which outputs, how many channels, which are depth, dense or the mask) are `trainers.tasks.TASKS`
entries with network "pix2pix"; `task_generator`, `task_discriminator` and `targets_from_views` read them.

Choices (digest 1.9, where the thesis is vague): the U-Net-256 of pix2pix (8 levels of 4x4 stride-2 convolutions,
batch norm, LeakyReLU 0.2 down, ReLU up, dropout 0.5 in the 3 innermost decoder blocks, N(0, 0.02) weights); the
non-saturating adversarial loss; lambda = 100 on an L1 term taken over the foreground only (eq. 3.2); Adam 2e-4,
betas (0.5, 0.999). The generator ends in a sigmoid, so it predicts the [0, 1] maps the renderers store directly:
sigmoid(2a) = (tanh(a) + 1) / 2, i.e. pix2pix's tanh output on targets mapped to [-1, 1], rescaled. A channel that
must be right on the background too (the silhouette's mask, which `DepthMapCrown.from_silhouette` thresholds at
0.5) is a "dense" channel: its L1 term covers every pixel.
"""
from __future__ import annotations

from typing import Mapping, NamedTuple, Sequence

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from species.errors import TreefarmError

from .preprocess import KINDS
from .tasks import TASKS, Task, get_task

__all__ = ["Pix2PixError", "UNetGenerator", "PatchDiscriminator", "GlobalDiscriminator", "DISCRIMINATORS",
           "make_discriminator", "init_weights", "GeneratorLoss", "masked_l1", "generator_loss",
           "discriminator_loss", "make_optimizer", "pix2pix_step", "masked_depth_error", "pix2pix_task",
           "task_channels", "task_generator", "task_discriminator", "targets_from_views", "sketch_to_input",
           "L1_WEIGHT", "LEARNING_RATE", "BETAS", "NORMS"]

L1_WEIGHT = 100.0
LEARNING_RATE = 2e-4
BETAS = (0.5, 0.999)
_LEAKY_SLOPE = 0.2
_MAX_WIDTH_FACTOR = 8           # channels grow 1, 2, 4, 8 x width and stay at 8 x width deeper down
_MIN_DOWN = 5                   # pix2pix's U-Net: 4 widening levels plus the innermost one
NORMS = {"batch": nn.BatchNorm2d, "instance": lambda c: nn.InstanceNorm2d(c, affine=True)}


class Pix2PixError(TreefarmError):
    """A pix2pix network, task or batch was asked for with a value outside what it allows."""


def _norm(kind: str, channels: int) -> nn.Module:
    if kind not in NORMS:
        raise Pix2PixError(f"norm {kind!r} is unknown: allowed {', '.join(NORMS)}")
    return NORMS[kind](channels)


def _positive_int(name: str, value, minimum: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise Pix2PixError(f"{name} = {value!r} is invalid: allowed an integer >= {minimum}")
    return int(value)


def _channels(width: int, level: int) -> int:
    return width * min(2 ** level, _MAX_WIDTH_FACTOR)


def init_weights(module: nn.Module, generator: torch.Generator) -> nn.Module:
    """pix2pix's initialisation in place: conv and linear weights N(0, 0.02), norm scales N(1, 0.02), biases 0."""
    for m in module.modules():
        if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d, nn.Linear)):
            nn.init.normal_(m.weight, 0.0, 0.02, generator=generator)
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, (nn.BatchNorm2d, nn.InstanceNorm2d)) and m.weight is not None:
            nn.init.normal_(m.weight, 1.0, 0.02, generator=generator)
            nn.init.zeros_(m.bias)
    return module


def _default_generator(generator: torch.Generator | None) -> torch.Generator:
    # No global RNG: without a generator, a fixed seed, so two networks built alike are alike.
    return torch.Generator().manual_seed(0) if generator is None else generator


class _SeededDropout(nn.Module):
    """Dropout drawing its masks from a torch.Generator (not the global RNG); identity in eval mode."""

    def __init__(self, p: float, generator: torch.Generator):
        super().__init__()
        self.p, self.generator = float(p), generator

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training or self.p == 0.0:
            return x
        draw = torch.rand(x.shape, generator=self.generator, device=self.generator.device, dtype=x.dtype)
        keep = (draw.to(x.device) >= self.p).to(x.dtype)
        return x * keep / (1.0 - self.p)


class UNetGenerator(nn.Module):
    """pix2pix U-Net: `n_down` 4x4 stride-2 convolutions down, as many transposed ones up, skips between mirrors.

    in_channels, out_channels : image channels in and out.
    width   : channels of the first level; level i has width * min(2**i, 8) (64 = pix2pix's 54 M parameters).
    dropout : dropout probability in the n_down - 5 innermost decoder blocks (3 at the default n_down = 8).
    n_down  : levels; an input's height and width must be multiples of 2**n_down (256 px at 8 gives a 1x1
              bottleneck, 512 px a 2x2 one; smaller images take fewer levels: 64 px at 6, 32 px at 5). At least 5.
    norm    : "batch" (pix2pix) or "instance"; neither the outermost nor the innermost encoder level has one.
    generator : torch.Generator for the initial weights and the dropout masks (None: a fixed seed, 0).

    forward(x (B, in_channels, H, W) float32 in [0, 1]) -> (B, out_channels, H, W) float32 in (0, 1) (sigmoid).
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 64, dropout: float = 0.5,
                 n_down: int = 8, norm: str = "batch", generator: torch.Generator | None = None):
        super().__init__()
        self.in_channels = _positive_int("in_channels", in_channels)
        self.out_channels = _positive_int("out_channels", out_channels)
        self.width = _positive_int("width", width)
        self.n_down = _positive_int("n_down", n_down, _MIN_DOWN)
        if not 0.0 <= float(dropout) < 1.0:
            raise Pix2PixError(f"dropout = {dropout!r} is invalid: allowed [0, 1)")
        self.dropout = float(dropout)
        generator = _default_generator(generator)
        c = [_channels(self.width, i) for i in range(self.n_down)]
        innermost = self.n_down - 1
        down = [nn.Conv2d(self.in_channels, c[0], 4, 2, 1)]
        for i in range(1, self.n_down):
            # A bias before a norm is cancelled by it (pix2pix leaves it out); a 1x1 bottleneck has no norm.
            normed = i < innermost
            layers = [nn.LeakyReLU(_LEAKY_SLOPE), nn.Conv2d(c[i - 1], c[i], 4, 2, 1, bias=not normed)]
            if normed:
                layers.append(_norm(norm, c[i]))
            down.append(nn.Sequential(*layers))
        # up[i] undoes down[i]: it takes level i's features (concatenated with its skip, except innermost).
        up = [nn.Sequential(nn.ReLU(), nn.ConvTranspose2d(2 * c[0], self.out_channels, 4, 2, 1), nn.Sigmoid())]
        for i in range(1, self.n_down):
            layers = [nn.ReLU(), nn.ConvTranspose2d(c[i] if i == innermost else 2 * c[i], c[i - 1], 4, 2, 1,
                                                    bias=False), _norm(norm, c[i - 1])]
            if i >= _MIN_DOWN and self.dropout > 0:
                layers.append(_SeededDropout(self.dropout, generator))
            up.append(nn.Sequential(*layers))
        self.down, self.up = nn.ModuleList(down), nn.ModuleList(up)
        init_weights(self, generator)

    @property
    def size_multiple(self) -> int:
        """Height and width of an input must be multiples of this (2**n_down)."""
        return 2 ** self.n_down

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not torch.jit.is_tracing():
            _check_image(x, self.in_channels, self.size_multiple, "UNetGenerator input")
        skips = []
        for block in self.down:
            x = block(x)
            skips.append(x)
        x = self.up[-1](skips[-1])
        for i in range(self.n_down - 2, -1, -1):
            x = self.up[i](torch.cat([x, skips[i]], dim=1))
        return x


def _check_image(x: torch.Tensor, channels: int, multiple: int, what: str) -> None:
    if x.ndim != 4 or x.shape[1] != channels or x.shape[2] % multiple or x.shape[3] % multiple:
        raise Pix2PixError(f"{what} has shape {tuple(x.shape)}: allowed (B, {channels}, H, W) with H and W "
                           f"multiples of {multiple}")


class PatchDiscriminator(nn.Module):
    """pix2pix's 70x70 PatchGAN conditioned on the input: one real/fake logit per overlapping 70x70 patch.

    in_channels, out_channels : channels of the condition (sketch) and of the judged image (depth).
    width, n_layers : first level's channels and the number of stride-2 levels (3 gives the 70 px field).
    forward(condition (B, in, H, W), image (B, out, H, W)) -> logits (B, 1, H/8 - 2, W/8 - 2) (30x30 at 256 px).
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 64, n_layers: int = 3,
                 norm: str = "batch", generator: torch.Generator | None = None):
        super().__init__()
        self.in_channels = _positive_int("in_channels", in_channels)
        self.out_channels = _positive_int("out_channels", out_channels)
        width, n_layers = _positive_int("width", width), _positive_int("n_layers", n_layers)
        layers = [nn.Conv2d(self.in_channels + self.out_channels, width, 4, 2, 1), nn.LeakyReLU(_LEAKY_SLOPE)]
        for i in range(1, n_layers + 1):
            stride = 2 if i < n_layers else 1
            layers += [nn.Conv2d(_channels(width, i - 1), _channels(width, i), 4, stride, 1, bias=False),
                       _norm(norm, _channels(width, i)), nn.LeakyReLU(_LEAKY_SLOPE)]
        layers.append(nn.Conv2d(_channels(width, n_layers), 1, 4, 1, 1))
        self.net = nn.Sequential(*layers)
        init_weights(self, _default_generator(generator))

    def forward(self, condition: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([condition, image], dim=1))


class GlobalDiscriminator(nn.Module):
    """The thesis's discriminator (digest 1.9): 4x4 stride-2 convolutions with batch norm and LeakyReLU, then one
    fully connected layer: a single logit for the whole image (the sigmoid is in the loss, for stability).

    image_size : the square size it judges (the FC layer fixes it); a multiple of 2**n_layers.
    forward(condition (B, in, S, S), image (B, out, S, S)) -> logits (B, 1).
    """

    def __init__(self, in_channels: int, out_channels: int, width: int = 64, image_size: int = 256,
                 n_layers: int = 5, norm: str = "batch", generator: torch.Generator | None = None):
        super().__init__()
        self.in_channels = _positive_int("in_channels", in_channels)
        self.out_channels = _positive_int("out_channels", out_channels)
        width, n_layers = _positive_int("width", width), _positive_int("n_layers", n_layers)
        self.image_size = _positive_int("image_size", image_size)
        if self.image_size % 2 ** n_layers:
            raise Pix2PixError(f"image_size = {image_size} is invalid for {n_layers} layers: allowed multiples "
                               f"of {2 ** n_layers}")
        layers = [nn.Conv2d(self.in_channels + self.out_channels, width, 4, 2, 1), nn.LeakyReLU(_LEAKY_SLOPE)]
        for i in range(1, n_layers):
            layers += [nn.Conv2d(_channels(width, i - 1), _channels(width, i), 4, 2, 1, bias=False),
                       _norm(norm, _channels(width, i)), nn.LeakyReLU(_LEAKY_SLOPE)]
        side = self.image_size // 2 ** n_layers
        layers += [nn.Flatten(), nn.Linear(_channels(width, n_layers - 1) * side * side, 1)]
        self.net = nn.Sequential(*layers)
        init_weights(self, _default_generator(generator))

    def forward(self, condition: torch.Tensor, image: torch.Tensor) -> torch.Tensor:
        if condition.shape[-2:] != (self.image_size, self.image_size):
            raise Pix2PixError(f"GlobalDiscriminator built for {self.image_size} px got images of "
                               f"{tuple(condition.shape[-2:])}")
        return self.net(torch.cat([condition, image], dim=1))


DISCRIMINATORS = {"patch": PatchDiscriminator, "global": GlobalDiscriminator}


def make_discriminator(kind: str, in_channels: int, out_channels: int, width: int = 64, image_size: int = 256,
                       generator: torch.Generator | None = None) -> nn.Module:
    """A discriminator by name: "patch" (70x70 PatchGAN, the production default) or "global" (the thesis's)."""
    if kind not in DISCRIMINATORS:
        raise Pix2PixError(f"discriminator {kind!r} is unknown: allowed {', '.join(DISCRIMINATORS)}")
    if kind == "global":
        return GlobalDiscriminator(in_channels, out_channels, width, image_size, generator=generator)
    return PatchDiscriminator(in_channels, out_channels, width, generator=generator)


class GeneratorLoss(NamedTuple):
    """The generator's loss: total = adversarial + l1_weight * l1 (scalar tensors)."""

    total: torch.Tensor
    adversarial: torch.Tensor
    l1: torch.Tensor


def _loss_weights(target: torch.Tensor, mask: torch.Tensor, dense_channels: Sequence[int]) -> torch.Tensor:
    if mask.shape[0] != target.shape[0] or mask.shape[1] != 1 or mask.shape[2:] != target.shape[2:]:
        raise Pix2PixError(f"mask of shape {tuple(mask.shape)} does not fit a target of shape "
                           f"{tuple(target.shape)}: allowed (B, 1, H, W)")
    channels = target.shape[1]
    dense = torch.zeros(channels, dtype=torch.bool, device=target.device)
    for c in dense_channels:
        if not 0 <= c < channels:
            raise Pix2PixError(f"dense channel {c} is invalid for {channels} target channels")
        dense[c] = True
    return torch.where(dense[None, :, None, None], torch.ones_like(target), mask.to(target.dtype).expand_as(target))


def masked_l1(prediction: torch.Tensor, target: torch.Tensor, mask: torch.Tensor,
              dense_channels: Sequence[int] = ()) -> torch.Tensor:
    """Eq. 3.2 as a mean: per channel, the mean |prediction - target| over the foreground (mask > 0; every pixel
    for `dense_channels`), averaged over channels. (B, C, H, W) tensors and mask (B, 1, H, W); a scalar tensor.
    Background pixels of the other channels add nothing, not even a gradient."""
    weights = _loss_weights(target, mask, dense_channels)
    per_channel = (weights * (prediction - target).abs()).sum(dim=(0, 2, 3))
    return (per_channel / weights.sum(dim=(0, 2, 3)).clamp(min=1.0)).mean()


def generator_loss(d_fake: torch.Tensor, prediction: torch.Tensor, target: torch.Tensor, mask: torch.Tensor,
                   l1_weight: float = L1_WEIGHT, dense_channels: Sequence[int] = ()) -> GeneratorLoss:
    """cGAN (non-saturating: the discriminator's logits on fakes pushed towards "real") + l1_weight * masked L1."""
    adversarial = F.binary_cross_entropy_with_logits(d_fake, torch.ones_like(d_fake))
    l1 = masked_l1(prediction, target, mask, dense_channels)
    return GeneratorLoss(adversarial + l1_weight * l1, adversarial, l1)


def discriminator_loss(d_real: torch.Tensor, d_fake: torch.Tensor) -> torch.Tensor:
    """Half the cross-entropy of logits on real pairs (label 1) plus fake pairs (label 0), as pix2pix halves it."""
    real = F.binary_cross_entropy_with_logits(d_real, torch.ones_like(d_real))
    fake = F.binary_cross_entropy_with_logits(d_fake, torch.zeros_like(d_fake))
    return 0.5 * (real + fake)


def make_optimizer(module: nn.Module, lr: float = LEARNING_RATE,
                   betas: tuple[float, float] = BETAS) -> torch.optim.Adam:
    """pix2pix's Adam for a generator or a discriminator: lr 2e-4, betas (0.5, 0.999)."""
    return torch.optim.Adam(module.parameters(), lr=lr, betas=betas)


def _unpack(batch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    if isinstance(batch, Mapping):
        missing = [k for k in ("input", "target", "mask") if k not in batch]
        if missing:
            raise Pix2PixError(f"batch lacks {', '.join(missing)}: allowed a dict with input, target, mask")
        return batch["input"], batch["target"], batch["mask"]
    if isinstance(batch, (tuple, list)) and len(batch) == 3:
        return tuple(batch)
    raise Pix2PixError(f"batch of type {type(batch).__name__} is invalid: allowed (input, target, mask) or a dict "
                       f"with those keys, (B, C, H, W) tensors")


def pix2pix_step(generator: nn.Module, discriminator: nn.Module, opt_g: torch.optim.Optimizer,
                 opt_d: torch.optim.Optimizer, batch, l1_weight: float = L1_WEIGHT,
                 dense_channels: Sequence[int] = ()) -> dict[str, float]:
    """One alternating update, discriminator first then generator, on a batch (input, target, mask) as
    `targets_from_views` gives them, stacked. Puts both networks in train mode.

    Returns floats: loss_d, loss_g (total), loss_g_gan, loss_g_l1 (the unweighted masked L1).
    """
    x, y, mask = _unpack(batch)
    generator.train()
    discriminator.train()
    fake = generator(x)

    opt_d.zero_grad(set_to_none=True)
    loss_d = discriminator_loss(discriminator(x, y), discriminator(x, fake.detach()))
    loss_d.backward()
    opt_d.step()

    opt_g.zero_grad(set_to_none=True)
    discriminator.requires_grad_(False)  # the generator's step needs gradients through D, not for D
    try:
        loss_g = generator_loss(discriminator(x, fake), fake, y, mask, l1_weight, dense_channels)
    finally:
        discriminator.requires_grad_(True)
    loss_g.total.backward()
    opt_g.step()
    return {"loss_d": loss_d.item(), "loss_g": loss_g.total.item(), "loss_g_gan": loss_g.adversarial.item(),
            "loss_g_l1": loss_g.l1.item()}


def masked_depth_error(prediction, target, mask, channels: Sequence[int] | None = None) -> float:
    """Mean absolute error over the foreground (mask > 0) of [0, 1] depth, pooled over the batch: the thesis's
    metric. prediction, target : (C, H, W) or (B, C, H, W) tensors or arrays; mask (1, H, W) or (B, 1, H, W);
    channels : the depth channels to score (default all; the tasks name theirs in `depth_channels`)."""
    p, t, m = (torch.as_tensor(np.asarray(a) if not isinstance(a, torch.Tensor) else a).detach().double()
               for a in (prediction, target, mask))
    if p.ndim == 3:
        p, t, m = p[None], t[None], m[None]
    if p.shape != t.shape or p.ndim != 4:
        raise Pix2PixError(f"prediction {tuple(p.shape)} and target {tuple(t.shape)} must be one (B, C, H, W) shape")
    chosen = list(range(p.shape[1])) if channels is None else list(channels)
    if not chosen or any(not 0 <= c < p.shape[1] for c in chosen):
        raise Pix2PixError(f"channels {chosen} are invalid for {p.shape[1]} channels")
    weights = _loss_weights(t, m, ())[:, chosen]
    total = weights.sum()
    if total == 0:
        raise Pix2PixError("masked_depth_error needs a foreground pixel: the mask is empty")
    return float((weights * (p[:, chosen] - t[:, chosen]).abs()).sum() / total)


def pix2pix_task(task: str | Task) -> Task:
    """A pix2pix task of `trainers.tasks.TASKS` by name, or the task itself; a task another network learns raises
    Pix2PixError (an unknown name, `get_task`'s TrainingDataError)."""
    task = get_task(task)
    if task.network != "pix2pix":
        raise Pix2PixError(f"task {task.name!r} is learnt by {task.network}, not pix2pix: allowed "
                           f"{', '.join(name for name, t in TASKS.items() if t.network == 'pix2pix')}")
    return task


def task_channels(task: str | Task) -> tuple[int, int]:
    """(input channels, target channels) of a pix2pix task's networks."""
    task = pix2pix_task(task)
    return KINDS[task.input_kind], task.out_channels


def task_generator(task: str | Task, width: int = 64, **kwargs) -> UNetGenerator:
    """The task's U-Net (channels fixed by the task; width and the other settings passed on)."""
    return UNetGenerator(*task_channels(task), width, **kwargs)


def task_discriminator(task: str | Task, kind: str = "patch", width: int = 64, image_size: int = 256,
                       generator: torch.Generator | None = None) -> nn.Module:
    """The task's discriminator by kind ("patch" or "global"), for its input and target channels."""
    return make_discriminator(kind, *task_channels(task), width, image_size, generator)


# depth01 maps are stored as 16-bit PNG on [0, 1]: background is exactly 65535; anything below is a surface.
_FAR_PLANE = 1.0 - 0.5 / 65535


def _as_chw(name: str, image, channels: int) -> torch.Tensor:
    image = image if isinstance(image, torch.Tensor) else torch.from_numpy(np.ascontiguousarray(image))
    if image.ndim == 2 and channels == 1:
        image = image[None]
    if image.ndim != 3 or image.shape[0] != channels:
        raise Pix2PixError(f"output {name!r} has shape {tuple(image.shape)}: allowed ({channels}, H, W) as "
                           f"farm.dataset.torch_dataset.ViewsDataset decodes it")
    return image


def sketch_to_input(image, channels: int) -> torch.Tensor:
    """The networks' input from a sketch as the renderers draw it, (C, H, W) uint8, dark ink on white (255):
    float32 ink = 1 - pixel / 255, so the background is 0 and strokes keep distinct colours."""
    image = _as_chw("sketch", image, channels)
    if image.dtype != torch.uint8:
        raise Pix2PixError(f"sketch has dtype {image.dtype}: allowed uint8, dark on white")
    return 1.0 - image.to(torch.float32) / 255.0


def targets_from_views(task: str | Task, item: Mapping) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(input (C_in, H, W) float32 in [0, 1], target (C_out, H, W) float32 in [0, 1], mask (1, H, W) float32 0/1)
    from one decoded view of a pix2pix task (a `trainers.tasks.Task` or its name): a `ViewsDataset` item (or any
    mapping of output name -> (C, H, W) tensor or array).

    pix2pix-silhouette: sketch_edges (uint8, black on white) -> silhouette_envelope (front, gap, mask); mask = its
    mask. pix2pix-trunk: trunk_strokes (uint8 RGB on white) -> trunk_depth; mask = trunk_depth < 1.
    """
    task = pix2pix_task(task)
    in_channels, out_channels = task_channels(task)
    source, target_name = task.inputs[0], task.targets[0]
    missing = [n for n in (source, target_name) if n not in item]
    if missing:
        raise Pix2PixError(f"the {task.name} task needs output {missing[0]!r}, which this view lacks: make the "
                           f"data with trainers/specs/{task.spec_name}.yaml")
    x = sketch_to_input(item[source], in_channels)
    target = _as_chw(target_name, item[target_name], out_channels)
    if not torch.is_floating_point(target):
        raise Pix2PixError(f"output {target_name!r} has dtype {target.dtype}: allowed float in [0, 1]")
    target = target.to(torch.float32)
    if x.shape[1:] != target.shape[1:]:
        raise Pix2PixError(f"{source} is {tuple(x.shape[1:])} px but {target_name} is "
                           f"{tuple(target.shape[1:])} px: they must match")
    if task.mask_channel is None:
        mask = target[:1] < _FAR_PLANE
    else:
        mask = target[task.mask_channel][None] >= 0.5
    return x, target, mask.to(torch.float32)
