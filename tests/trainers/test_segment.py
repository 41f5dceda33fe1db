"""The tree mask network (issue 51): its shapes, that training lowers its loss, that its ONNX file reproduces torch
at any photo size, that the shipped model finds the tree in renders it never saw, and that a bad model is refused
in one line."""
from __future__ import annotations

import numpy as np
import pytest
import torch

import species
from reconstruct.photo_folder import PhotoError
from reconstruct.photo_masks import MASK_TASK, MaskNetwork, mask_network
from reconstruct.scoring import crowns
from renderers.views import ViewRenderer
from trainers.models import ModelFilesError, load, predictor_from_folder
from trainers.networks import SegmentNetwork, TrainSettings
from trainers.onnx_runtime import OnnxModel
from trainers.segment import MaskUNet, SegmentError, augment_photo, mask_iou, mask_loss
from trainers.tasks import TASKS

torch.set_num_threads(1)

# The issue's target for masks on renders, pooled over the held-out views below, on the crowns' outlines (the gaps
# between branches closed: what the visual hull carves with); pixel by pixel a floor under the measured value
# (speckled leaves and 1 px twigs at this size).
MIN_CROWN_IOU = 0.9
MIN_PIXEL_IOU = 0.75
# Trees the training spec (seed 5151) never drew: other presets' draws from other seeds.
HELD_OUT = (("sc_broad_oak", 900001), ("sc_open_fruit_tree", 900002), ("silver_birch", 900003),
            ("sc_spruce", 900004))


def _tiny_network(seed: int = 0) -> SegmentNetwork:
    return SegmentNetwork(TASKS[MASK_TASK], TrainSettings(width=4, seed=seed)).build()


def test_the_network_keeps_the_photos_size_and_refuses_other_shapes():
    net = MaskUNet(3, 4)
    assert net(torch.rand(2, 3, 64, 96)).shape == (2, 1, 64, 96)
    with pytest.raises(SegmentError, match=r"allowed \(B, 3, H, W\) with H and W multiples of 8"):
        net(torch.rand(1, 3, 60, 64))
    with pytest.raises(SegmentError, match="width = 0 is invalid"):
        MaskUNet(3, 0)
    assert sum(p.numel() for p in MaskUNet(3, TASKS[MASK_TASK].recipe["width"]).parameters()) < 200_000


def test_a_few_training_steps_lower_the_loss():
    rng = np.random.default_rng(0)
    photos = rng.uniform(0.0, 1.0, (8, 3, 32, 32)).astype(np.float32)
    target = np.zeros((8, 1, 32, 32), np.float32)
    target[:, :, 8:24, 12:20] = 1.0
    photos[:, 1:2][target > 0] = 1.0                     # a green trunk on noise
    network = _tiny_network()
    optimizers = network.optimizers()
    batch = {"input": photos, "target": target, "mask": np.ones_like(target)}
    losses = [network.train_step(optimizers, batch)["loss"] for _ in range(15)]
    assert losses[-1] < 0.8 * losses[0]


def test_onnx_matches_torch_at_a_phone_photos_aspect(tmp_path):
    network = _tiny_network(seed=3)
    with torch.no_grad():                                 # batch-norm statistics away from the initial identity
        network.modules["model"].train()(torch.rand(4, 3, 64, 64, generator=torch.Generator().manual_seed(1)))
    files = network.export(tmp_path)
    x = torch.rand(2, 3, 72, 128, generator=torch.Generator().manual_seed(2))
    expected = network.predict(x.numpy()).numpy()
    model = OnnxModel(files["tree-mask.onnx"], {"photo": (None, 3, None, None)}, {"mask": (None, 1, None, None)})
    got = model.run(x.numpy())
    assert got.shape == (2, 1, 72, 128) and np.abs(got - expected).max() < 1e-4


def test_the_augmentation_moves_photo_and_mask_alike_and_repeats_with_its_seed():
    photo = np.zeros((3, 64, 64), np.float32)
    photo[:, 20:40, 28:36] = 0.8
    mask = (photo[:1] > 0).astype(np.float32)
    a = augment_photo(photo, np.random.default_rng(5), [(mask, (0.0,))])
    b = augment_photo(photo, np.random.default_rng(5), [(mask, (0.0,))])
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1][0], b[1][0])
    moved, (moved_mask,) = a
    assert mask_iou(moved.max(axis=0, keepdims=True) > 0.3, moved_mask) > 0.8


@pytest.fixture(scope="module")
def held_out_views():
    """(photos (V, 192, 192, 3) uint8, the renderer's tree masks (V, 192, 192) bool) of trees the training spec
    never drew, each from four jittered orbit views: the shipped spec's own outputs."""
    renderer = ViewRenderer(192)
    photos, masks = [], []
    try:
        for preset, seed in HELD_OUT:
            skeleton, mesh = species.rebuild(species.sample(preset, np.random.default_rng(seed)))
            for view in renderer.render(mesh, skeleton, "orbit:2:5,25:jitter", ["photo", "photo_mask"],
                                        np.random.default_rng(seed)):
                photos.append(view.images["photo"])
                masks.append(view.images["photo_mask"] > 0)
    finally:
        renderer.close()
    return np.stack(photos), np.stack(masks)


def test_the_shipped_model_finds_the_tree_in_renders_it_never_saw(held_out_views):
    photos, truth = held_out_views
    network = mask_network()
    found = np.stack([network.mask(photo) for photo in photos])
    assert mask_iou(crowns(found), crowns(truth)) >= MIN_CROWN_IOU
    assert mask_iou(found, truth) >= MIN_PIXEL_IOU


def test_a_bad_model_or_mask_kind_is_one_line(tmp_path):
    with pytest.raises(PhotoError, match="masks 'deep' is not known: allowed network, classical"):
        mask_network("deep")
    assert mask_network("classical") is None
    with pytest.raises(Exception, match=str(tmp_path / "none")) as missing:
        mask_network(models=str(tmp_path / "none"))
    assert "\n" not in str(missing.value)
    with pytest.raises(ModelFilesError, match="holds a pix2pix-trunk model, not tree-mask"):
        predictor_from_folder(load("pix2pix-trunk").folder, MASK_TASK)
    with pytest.raises(PhotoError, match="allowed a tree-mask model"):
        MaskNetwork(load("pix2pix-trunk"))
