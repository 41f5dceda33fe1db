"""ONNX export and onnxruntime inference: the file reproduces torch, takes any batch, and OnnxModel refuses a file
whose inputs, outputs or bytes are not what the code expects, with one clear error."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from trainers.onnx_runtime import OnnxModel, OnnxModelError, export_onnx
from trainers.pix2pix import task_generator

torch.set_num_threads(1)

SKETCH = {"sketch": (None, 1, 256, 256)}
SILHOUETTE = {"silhouette": (None, 3, 256, 256)}


@pytest.fixture(scope="module")
def unet_file(tmp_path_factory):
    net = task_generator("pix2pix-silhouette", width=4, generator=torch.Generator().manual_seed(0))
    # A few training steps' worth of batch-norm statistics, so eval mode differs from the initial identity.
    with torch.no_grad():
        net.train()(torch.rand(4, 1, 256, 256, generator=torch.Generator().manual_seed(1)))
    path = export_onnx(net, torch.rand(1, 1, 256, 256), tmp_path_factory.mktemp("onnx") / "silhouette.onnx",
                       ["sketch"], ["silhouette"])
    return net, path


def test_export_matches_torch_within_1e_4_at_another_batch_size(unet_file):
    net, path = unet_file
    assert net.training  # export restores the mode it found
    x = torch.rand(3, 1, 256, 256, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        expected = net.eval()(x).numpy()
    net.train()
    got = OnnxModel(path, SKETCH, SILHOUETTE).run(x.numpy())
    assert got.shape == (3, 3, 256, 256)
    assert np.abs(got - expected).max() < 1e-4


def test_export_leaves_only_the_finished_file(unet_file):
    _, path = unet_file
    assert [p.name for p in path.parent.iterdir()] == ["silhouette.onnx"]


def test_session_uses_one_intra_op_thread_by_default(unet_file):
    model = OnnxModel(unet_file[1], SKETCH, SILHOUETTE)
    assert model.session.get_session_options().intra_op_num_threads == 1


def test_wrong_input_channels_are_refused_naming_the_input_and_both_shapes(unet_file):
    with pytest.raises(OnnxModelError, match=r"'sketch' has shape \(B, 1, 256, 256\); the code expects "
                                             r"\(B, 3, 256, 256\)"):
        OnnxModel(unet_file[1], {"sketch": (None, 3, 256, 256)}, SILHOUETTE)


def test_wrong_image_size_is_refused(unet_file):
    with pytest.raises(OnnxModelError, match="512"):
        OnnxModel(unet_file[1], SKETCH, {"silhouette": (None, 3, 512, 512)})


def test_wrong_output_names_are_refused_naming_both(unet_file):
    with pytest.raises(OnnxModelError, match=r"outputs \['silhouette'\]; the code expects \['trunk_depth'\]"):
        OnnxModel(unet_file[1], SKETCH, {"trunk_depth": (None, 1, 256, 256)})


def test_wrong_dtype_is_refused(unet_file):
    with pytest.raises(OnnxModelError, match="dtype float32; the code expects float16"):
        OnnxModel(unet_file[1], SKETCH, SILHOUETTE, dtype="float16")


@pytest.mark.parametrize("content", [b"not an onnx file at all" * 10, "truncated"])
def test_a_corrupt_file_gives_one_clear_error(unet_file, tmp_path, content):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(unet_file[1].read_bytes()[:5000] if content == "truncated" else content)
    with pytest.raises(OnnxModelError, match=r"bad.onnx cannot be loaded \(corrupt or not an ONNX model\)") as info:
        OnnxModel(bad, SKETCH, SILHOUETTE)
    assert "\n" not in str(info.value)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(OnnxModelError, match="nothing.onnx does not exist"):
        OnnxModel(tmp_path / "nothing.onnx", SKETCH, SILHOUETTE)


def test_run_rejects_an_input_of_the_wrong_shape_or_kind(unet_file):
    model = OnnxModel(unet_file[1], SKETCH, SILHOUETTE)
    with pytest.raises(OnnxModelError, match=r"shape \(1, 256, 256\)"):
        model.run(np.zeros((1, 256, 256), np.float32))
    with pytest.raises(OnnxModelError, match="dtype uint8"):
        model.run(np.zeros((1, 1, 256, 256), np.uint8))


class _TwoHeads(torch.nn.Module):
    """A stand-in for TreeSketchNet: two inputs' worth of features, several named heads returned as a dict."""

    def __init__(self):
        super().__init__()
        self.body = torch.nn.Sequential(torch.nn.Conv2d(1, 4, 3, 2, 1), torch.nn.AdaptiveAvgPool2d(1),
                                        torch.nn.Flatten())
        self.ranges = torch.nn.Linear(4, 5)
        self.species = torch.nn.Linear(4, 3)

    def forward(self, sketch):
        features = self.body(sketch)
        return {"species": self.species(features), "ranges": self.ranges(features)}


def test_a_model_with_named_heads_exports_and_runs_as_a_dict(tmp_path):
    net = _TwoHeads().eval()
    path = export_onnx(net, torch.rand(1, 1, 64, 64), tmp_path / "heads.onnx", ["sketch"], ["ranges", "species"])
    model = OnnxModel(path, {"sketch": (None, 1, 64, 64)}, {"ranges": (None, 5), "species": (None, 3)})
    x = torch.rand(2, 1, 64, 64, generator=torch.Generator().manual_seed(0))
    out = model.run({"sketch": x.numpy()})
    with torch.no_grad():
        expected = net(x)
    assert set(out) == {"ranges", "species"}
    for name in out:
        assert np.abs(out[name] - expected[name].numpy()).max() < 1e-5


def test_export_refuses_output_names_that_differ_from_the_heads(tmp_path):
    with pytest.raises(OnnxModelError, match="returns outputs"):
        export_onnx(_TwoHeads(), torch.rand(1, 1, 64, 64), tmp_path / "h.onnx", ["sketch"], ["ranges", "params"])
    assert not list(tmp_path.iterdir())


def test_an_instance_norm_trunk_unet_exports_too(tmp_path):
    net = task_generator("pix2pix-trunk", width=4, n_down=6, norm="instance").eval()
    path = export_onnx(net, torch.rand(1, 3, 64, 64), tmp_path / "trunk.onnx", ["strokes"], ["trunk_depth"])
    x = torch.rand(2, 3, 64, 64, generator=torch.Generator().manual_seed(3))
    got = OnnxModel(path, {"strokes": (None, 3, 64, 64)}, {"trunk_depth": (None, 1, 64, 64)}).run(x.numpy())
    with torch.no_grad():
        assert np.abs(got - net(x).numpy()).max() < 1e-4
