"""pix2pix networks, losses, step and task data: shapes, the masked L1's indifference to the background, a tiny
U-Net overfitting a few samples, the depth metric's known answer, and views decoded into (input, target, mask)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from farm.dataset.image_codec import decode_map, encode_map
from trainers.pix2pix import (GlobalDiscriminator, PatchDiscriminator, Pix2PixError, UNetGenerator,
                              discriminator_loss, generator_loss, make_discriminator, make_optimizer,
                              masked_depth_error, masked_l1, pix2pix_step, targets_from_views, task_channels,
                              task_discriminator, task_generator)
from trainers.tasks import TASKS, TrainingDataError

torch.set_num_threads(1)


def _seeded(seed: int) -> torch.Generator:
    return torch.Generator().manual_seed(seed)


@pytest.mark.parametrize("task, channels", [("pix2pix-silhouette", (1, 3)), ("pix2pix-trunk", (3, 1))])
def test_unet_maps_a_256_px_sketch_to_the_task_channels_in_0_1(task, channels):
    assert task_channels(task) == channels
    net = task_generator(task, width=4).eval()
    x = torch.rand(2, channels[0], 256, 256, generator=_seeded(0))
    with torch.no_grad():
        y = net(x)
    assert y.shape == (2, channels[1], 256, 256)
    assert y.dtype == torch.float32 and float(y.min()) >= 0.0 and float(y.max()) <= 1.0


def test_unet_at_width_64_is_pix2pix_size():
    # pix2pix's unet_256 (3 -> 3 channels, 64 filters) has 54.41 M parameters.
    count = sum(p.numel() for p in UNetGenerator(3, 3, 64).parameters())
    assert 54.40e6 < count < 54.42e6


def test_unet_runs_at_512_px_and_at_64_px_with_6_levels():
    with torch.no_grad():
        assert UNetGenerator(1, 3, 2).eval()(torch.rand(1, 1, 512, 512)).shape == (1, 3, 512, 512)
        assert UNetGenerator(1, 3, 4, n_down=6).eval()(torch.rand(1, 1, 64, 64)).shape == (1, 3, 64, 64)


def test_unet_rejects_a_size_that_is_not_a_multiple_of_2_to_the_levels():
    with pytest.raises(Pix2PixError, match="multiples of 256"):
        UNetGenerator(1, 3, 4)(torch.rand(1, 1, 200, 200))
    with pytest.raises(Pix2PixError, match=r"\(B, 1, H, W\)"):
        UNetGenerator(1, 3, 4)(torch.rand(1, 3, 256, 256))


@pytest.mark.parametrize("kwargs, message", [({"width": 0}, "width"), ({"n_down": 4}, "n_down"),
                                             ({"dropout": 1.0}, "dropout"), ({"norm": "layer"}, "norm")])
def test_unet_rejects_bad_settings(kwargs, message):
    with pytest.raises(Pix2PixError, match=message):
        UNetGenerator(1, 3, **{"width": 4, **kwargs})


def test_dropout_sits_in_the_three_innermost_decoder_blocks_and_only_in_training():
    net = UNetGenerator(1, 3, 4, generator=_seeded(0))
    with_dropout = [i for i, block in enumerate(net.up) if any(type(m).__name__ == "_SeededDropout" for m in block)]
    assert with_dropout == [5, 6, 7]  # up[7] takes the 1x1 bottleneck
    x = torch.rand(1, 1, 256, 256, generator=_seeded(1))
    net.eval()
    with torch.no_grad():
        assert torch.equal(net(x), net(x))


def test_same_generator_seed_gives_the_same_weights_and_dropout_masks():
    x = torch.rand(2, 1, 256, 256, generator=_seeded(1))
    a, b, c = (UNetGenerator(1, 3, 4, generator=_seeded(s)).train() for s in (7, 7, 8))
    assert all(torch.equal(p, q) for p, q in zip(a.parameters(), b.parameters()))
    assert not torch.equal(next(a.parameters()), next(c.parameters()))
    with torch.no_grad():
        assert torch.equal(a(x), b(x))


def test_patch_discriminator_judges_30x30_patches_of_a_256_px_pair():
    d = PatchDiscriminator(1, 3, width=4)
    out = d(torch.rand(2, 1, 256, 256), torch.rand(2, 3, 256, 256))
    assert out.shape == (2, 1, 30, 30)


def test_global_discriminator_gives_one_logit_per_image_and_only_at_its_size():
    d = make_discriminator("global", 3, 1, width=4, image_size=256)
    assert isinstance(d, GlobalDiscriminator)
    assert d(torch.rand(2, 3, 256, 256), torch.rand(2, 1, 256, 256)).shape == (2, 1)
    with pytest.raises(Pix2PixError, match="256 px"):
        d(torch.rand(1, 3, 128, 128), torch.rand(1, 1, 128, 128))
    with pytest.raises(Pix2PixError, match="'pixel' is unknown"):
        make_discriminator("pixel", 3, 1)


def _pair(seed: int, channels: int = 2, size: int = 16):
    g = _seeded(seed)
    pred = torch.rand(2, channels, size, size, generator=g)
    target = torch.rand(2, channels, size, size, generator=g)
    mask = (torch.rand(2, 1, size, size, generator=g) > 0.5).float()
    return pred, target, mask


def test_masked_l1_ignores_the_target_outside_the_mask():
    pred, target, mask = _pair(0)
    other = torch.where(mask > 0, target, torch.rand(target.shape, generator=_seeded(9)) + 5.0)
    assert torch.isclose(masked_l1(pred, target, mask), masked_l1(pred, other, mask), rtol=0, atol=1e-7)
    assert float(masked_l1(pred, target, mask)) > 0


def test_masked_l1_gives_no_gradient_outside_the_mask_except_on_dense_channels():
    pred, target, mask = _pair(1)
    pred.requires_grad_(True)
    masked_l1(pred, target, mask, dense_channels=(1,)).backward()
    background = (mask[:, 0] == 0)
    assert torch.all(pred.grad[:, 0][background] == 0)
    assert torch.all(pred.grad[:, 0][~background] != 0)
    assert torch.all(pred.grad[:, 1] != 0)


def test_masked_l1_known_answer():
    pred = torch.zeros(1, 1, 2, 2)
    target = torch.tensor([[[[0.2, 0.4], [9.0, 9.0]]]])
    mask = torch.tensor([[[[1.0, 1.0], [0.0, 0.0]]]])
    assert float(masked_l1(pred, target, mask)) == pytest.approx(0.3)


def test_generator_loss_is_cgan_plus_100_times_l1():
    pred, target, mask = _pair(2, channels=1)
    logits = torch.tensor([[0.0]])
    loss = generator_loss(logits, pred, target, mask)
    assert float(loss.adversarial) == pytest.approx(np.log(2.0))
    assert float(loss.total) == pytest.approx(float(loss.adversarial) + 100.0 * float(loss.l1))


def test_discriminator_loss_known_answers():
    assert float(discriminator_loss(torch.zeros(3, 1), torch.zeros(3, 1))) == pytest.approx(np.log(2.0))
    confident = discriminator_loss(torch.full((3, 1), 20.0), torch.full((3, 1), -20.0))
    assert float(confident) < 1e-8


def test_masked_depth_error_known_answer():
    pred = np.array([[[0.5, 0.5], [0.0, 0.0]]], np.float32)
    target = np.array([[[0.4, 0.8], [1.0, 1.0]]], np.float32)
    mask = np.array([[[1, 1], [0, 0]]], np.float32)
    assert masked_depth_error(pred, target, mask) == pytest.approx(0.2)
    with pytest.raises(Pix2PixError, match="mask is empty"):
        masked_depth_error(pred, target, np.zeros_like(mask))


def test_masked_depth_error_scores_only_the_named_channels():
    pred = torch.zeros(1, 3, 1, 1)
    target = torch.tensor([0.1, 0.3, 1.0]).reshape(1, 3, 1, 1)
    mask = torch.ones(1, 1, 1, 1)
    assert masked_depth_error(pred, target, mask, channels=(0, 1)) == pytest.approx(0.2)


def test_a_tiny_unet_overfits_a_few_samples():
    g = _seeded(3)
    n, size = 4, 32
    blobs = torch.nn.functional.max_pool2d((torch.rand(n, 1, size, size, generator=g) > 0.97).float(), 5, 1, 2)
    ramp = torch.linspace(0, 1, size)[None, None, :, None]
    target = torch.where(blobs > 0, 0.3 + 0.4 * ramp * torch.rand(n, 1, 1, 1, generator=g), torch.ones(1))
    strokes = blobs * torch.rand(n, 3, 1, 1, generator=g)
    task = TASKS["pix2pix-trunk"]
    net = task_generator(task, width=8, n_down=5, generator=_seeded(0))
    disc = task_discriminator(task, width=8, generator=_seeded(1))
    opt_g, opt_d = make_optimizer(net), make_optimizer(disc)
    losses = [pix2pix_step(net, disc, opt_g, opt_d, {"input": strokes, "target": target, "mask": blobs})
              for _ in range(300)]
    assert set(losses[0]) == {"loss_d", "loss_g", "loss_g_gan", "loss_g_l1"}
    assert all(isinstance(v, float) for v in losses[-1].values())
    assert losses[-1]["loss_g_l1"] <= 0.1 * losses[0]["loss_g_l1"]


def test_pix2pix_step_rejects_a_batch_without_a_mask():
    task = TASKS["pix2pix-trunk"]
    net, disc = task_generator(task, width=2, n_down=5), task_discriminator(task, width=2)
    with pytest.raises(Pix2PixError, match="mask"):
        pix2pix_step(net, disc, make_optimizer(net), make_optimizer(disc),
                     {"input": torch.rand(1, 3, 32, 32), "target": torch.rand(1, 1, 32, 32)})


def _stored(name: str, image: np.ndarray) -> torch.Tensor:
    """An image through the views table's PNG codec and the ViewsDataset layout (C, H, W)."""
    png, scale, offset = encode_map(name, image)
    decoded = decode_map(png, scale, offset)
    return torch.from_numpy(decoded[None] if decoded.ndim == 2 else np.moveaxis(decoded, 2, 0).copy())


def test_silhouette_views_become_ink_input_and_the_silhouette_with_its_mask():
    rng = np.random.default_rng(0)
    edges = np.where(rng.random((8, 8)) > 0.8, 0, 255).astype(np.uint8)
    fg = np.zeros((8, 8), bool)
    fg[2:6, 1:7] = True
    silhouette = np.stack([np.where(fg, 0.4, 1.0), np.where(fg, 0.1, 0.0), fg], -1).astype(np.float32)
    views = {"sketch_edges": _stored("sketch_edges", edges),
             "silhouette_envelope": _stored("silhouette_envelope", silhouette)}
    x, target, mask = targets_from_views("pix2pix-silhouette", views)
    assert x.shape == (1, 8, 8) and target.shape == (3, 8, 8) and mask.shape == (1, 8, 8)
    assert torch.equal(x[0] == 1.0, torch.from_numpy(edges == 0)) and float(x.min()) == 0.0
    assert torch.equal(mask[0].bool(), torch.from_numpy(fg))
    assert torch.allclose(target, torch.from_numpy(np.moveaxis(silhouette, 2, 0)), atol=1e-4)


def test_trunk_views_give_a_mask_exactly_where_trunk_depth_is_below_1():
    depth = np.ones((8, 8), np.float32)
    depth[3, 2:6] = [0.2, 0.5, 0.9999, 0.7]
    strokes = np.full((8, 8, 3), 255, np.uint8)
    strokes[3, 2:6] = (255, 0, 0)
    x, target, mask = targets_from_views(TASKS["pix2pix-trunk"], {"trunk_strokes": _stored("trunk_strokes", strokes),
                                                                   "trunk_depth": _stored("trunk_depth", depth)})
    assert x.shape == (3, 8, 8) and target.shape == (1, 8, 8)
    assert torch.equal(mask[0].bool(), torch.from_numpy(depth < 1))
    assert torch.allclose(x[:, 3, 2], torch.tensor([0.0, 1.0, 1.0]))


def test_targets_from_views_names_the_missing_output_and_the_spec_that_makes_it():
    with pytest.raises(Pix2PixError, match="'trunk_depth'.*pix2pix-trunk.yaml"):
        targets_from_views("pix2pix-trunk", {"trunk_strokes": torch.zeros(3, 8, 8, dtype=torch.uint8)})
    with pytest.raises(TrainingDataError, match="'depth' is unknown"):
        targets_from_views("depth", {})
    with pytest.raises(Pix2PixError, match="'sketchnet' is learnt by sketchnet, not pix2pix"):
        targets_from_views("sketchnet", {})


def test_targets_from_views_rejects_a_float_sketch_and_mismatched_sizes():
    with pytest.raises(Pix2PixError, match="uint8"):
        targets_from_views("pix2pix-trunk", {"trunk_strokes": torch.zeros(3, 8, 8), "trunk_depth": torch.ones(1, 8, 8)})
    with pytest.raises(Pix2PixError, match="must match"):
        targets_from_views("pix2pix-trunk", {"trunk_strokes": torch.zeros(3, 8, 8, dtype=torch.uint8),
                                     "trunk_depth": torch.ones(1, 4, 4)})
