"""TreeSketchNet: the parameter codec (round trips that grow the same tree, decode that always grows), the network's
outputs, the masked loss, overfitting a handful of samples, the metrics and the ONNX export."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

import species
from species.errors import TreefarmError
from species.weber_penn import estimate_size, validate, WeberPennParams
from species.weber_penn.sapling_preset import REALIZED_ONLY_KEYS
from trainers.sketchnet import (SketchNetError, TreeSketchNet, export_onnx, grown_tree_errors, sketchnet_loss,
                                sketchnet_metrics)
from trainers.sketchnet_codec import (CODEC_VERSION, REGRESSION_HEADS, SPECIES_HEAD, CodecError, ParameterCodec,
                                      class_head, slot_names, weber_penn_species)

torch.set_num_threads(1)

SAPLING_DIR = Path(__file__).resolve().parents[3] / "shared" / "data" / "sapling"
TSN_FILES = sorted(SAPLING_DIR.glob("*.json"))
PRESETS = [p.name for p in species.list_presets("weber_penn")]
TINY = dict(width=0.25, depth=0.34)


def _preset_samples() -> list[dict]:
    rng = np.random.default_rng(2024)
    return [species.sample(name, rng) for name in PRESETS]


def _tsn_dicts() -> list[dict]:
    return [json.loads(path.read_text()) for path in TSN_FILES]


@pytest.fixture(scope="module")
def samples() -> list[dict]:
    return _preset_samples()


@pytest.fixture(scope="module")
def codec(samples) -> ParameterCodec:
    return ParameterCodec.fit(samples + _tsn_dicts())


def _without_rsplits2(params: dict) -> dict:
    return {k: v for k, v in params.items() if k != "rSplits2"}


def _float32_values(params: dict, keys: set[str]) -> dict:
    """`params` with the floats of `keys` rounded to float32, what float32 targets carry."""
    def rounded(value):
        if isinstance(value, float):
            return float(np.float32(value))
        return [rounded(v) for v in value] if isinstance(value, list) else value
    return {k: rounded(v) if k in keys else v for k, v in params.items()}


def _same_tree(a: dict, b: dict) -> None:
    first, second = (species.grow(d, np.random.default_rng(11)) for d in (a, b))
    assert first.n_nodes == second.n_nodes and first.n_leaves == second.n_leaves
    np.testing.assert_array_equal(first.positions, second.positions)
    np.testing.assert_array_equal(first.leaves, second.leaves)


# ------------------------------------------------------------------------------------------------ codec
def test_the_five_treesketchnet_dictionaries_are_at_hand():
    assert len(TSN_FILES) == 5


def test_codec_predicts_the_papers_61_keys_and_four_of_ours(codec):
    tsn_keys = set(_tsn_dicts()[0])
    paper = tsn_keys - {"seed", "rSplits2"} - {k for k in tsn_keys if k.startswith("prune")}
    assert len(paper) == 61
    assert paper <= set(codec.keys) and set(codec.keys) - paper == {"splitByLen", "autoTaper", "closeTip", "rMode"}
    per_head = {h: {name.split("[")[0] for name in slot_names(h)} for h in REGRESSION_HEADS}
    assert sum(len(keys) for keys in per_head.values()) + 9 == 61  # six range heads + nine categorical keys
    assert len(slot_names("angle")) == 12 * 4 + 5  # per-level keys hold 4 values, scalars 1


@pytest.mark.parametrize("index", range(len(PRESETS) + 5), ids=PRESETS + [p.stem for p in TSN_FILES])
def test_decode_of_float64_targets_grows_the_same_tree(codec, samples, index):
    # Exact, not close: the generator is discontinuous in its values (a rounding count, a split chance against
    # a draw), so one unit in the last place can grow another tree; the codec's power-of-two scaling is exact.
    params = _without_rsplits2((samples + _tsn_dicts())[index])
    decoded = codec.decode(codec.as_outputs(codec.encode(params, np.float64)), seed=5)
    assert "rSplits2" not in decoded and decoded["seed"] == 5 and decoded["draws"] == "realized"
    _same_tree(params, decoded)


@pytest.mark.parametrize("index", range(len(PRESETS) + 5), ids=PRESETS + [p.stem for p in TSN_FILES])
def test_decode_of_float32_targets_gives_the_float32_values_and_their_tree(codec, samples, index):
    params = _without_rsplits2((samples + _tsn_dicts())[index])
    decoded = codec.decode(codec.as_outputs(codec.encode(params)))
    predicted_floats = {name.split("[")[0] for head in REGRESSION_HEADS for name in slot_names(head)}
    reference = validate(_float32_values(params, predicted_floats))
    got = validate(decoded)
    for key in set(codec.keys):
        assert got[key] == reference[key], key
    _same_tree(_float32_values(params, predicted_floats), decoded)


def test_targets_are_normalised_and_masks_drop_unused_levels(codec, samples):
    maple = next(s for s in samples if s["species"] == "maple")  # levels = 2
    encoded = codec.encode(maple)
    assert all(encoded[h].dtype == np.float32 and np.abs(encoded[h]).max() <= 1.0 + 1e-6 for h in REGRESSION_HEADS)
    mask = dict(zip(slot_names("positive"), encoded["positive_mask"]))
    assert [mask[f"length[{i}]"] for i in range(4)] == [1, 1, 0, 0] and mask["scale"] == 1
    assert encoded[class_head("shapeS")].dtype == np.int64 and encoded[SPECIES_HEAD] == PRESETS.index("maple")


def test_an_absent_rlastang_is_masked_and_other_absent_draws_take_the_generators_value(codec, samples):
    params = {k: v for k, v in samples[0].items() if k not in ("rLastAng", "curveV1")}
    encoded = codec.encode(params, np.float64)
    mask = dict(zip(slot_names("angle"), encoded["angle_mask"]))
    assert all(mask[f"rLastAng[{i}]"] == 0 for i in range(4))
    values = dict(zip(slot_names("angle"), encoded["angle"]))
    assert [values[f"curveV1[{i}]"] for i in range(4)] == [0.0] * 4  # the generator's value when absent
    assert [mask[f"curveV1[{i}]"] for i in range(2)] == [1, 1]


def test_a_dictionary_without_species_has_no_species_label(codec):
    assert codec.encode(_tsn_dicts()[0])[SPECIES_HEAD] == -1
    assert weber_penn_species() == tuple(sorted(PRESETS)) == codec.species


@pytest.mark.parametrize("change, match", [
    ({"species": "banyan"}, "vocabulary"),
    ({"generator": "colonization"}, "Weber-Penn"),
    ({"draws": "ranges"}, "ranges"),
])
def test_encode_refuses_what_it_cannot_encode(codec, samples, change, match):
    params = {k: v for k, v in {**samples[0], **change}.items() if k not in REALIZED_ONLY_KEYS}
    with pytest.raises(CodecError, match=match):
        codec.encode(params)


def test_encode_names_a_bad_value(codec, samples):
    with pytest.raises(TreefarmError, match="levels"):
        codec.encode({**samples[0], "levels": 9})


def _random_outputs(codec, rng, scale=3.0, batch=1):
    return {name: rng.normal(0, scale, (batch, width)).astype(np.float32) for name, width in codec.output_sizes.items()}


def test_decode_of_any_outputs_validates_and_stays_in_the_size_budget(codec):
    rng = np.random.default_rng(3)
    batches = [_random_outputs(codec, rng, batch=40)]
    for fill in (1e30, -1e30, np.nan, np.inf, -np.inf, 0.0):
        batches.append({name: np.full((1, width), fill, np.float32) for name, width in codec.output_sizes.items()})
    limits = codec.to_dict()["limits"]
    trained_shapes = {validate(s)["shapeS"] for s in _preset_samples() + _tsn_dicts()}
    for outputs in batches:
        for params in codec.decode_batch(outputs):
            validated = validate(params)
            assert validated["shapeS"] in trained_shapes  # never an unseen class (shapeS 8 cannot grow)
            estimate = estimate_size(WeberPennParams.from_validated(validated, np.random.default_rng(0)))
            assert estimate.total_nodes <= limits["max_nodes"] and estimate.leaves <= limits["max_leaves"]
            json.dumps(params)


def test_decode_of_extreme_outputs_grows(codec):
    for fill in (1e30, -1e30):
        outputs = {name: np.full(width, fill, np.float32) for name, width in codec.output_sizes.items()}
        skeleton = species.grow(codec.decode(outputs), np.random.default_rng(0))
        assert skeleton.n_nodes > 1 and np.isfinite(skeleton.positions).all()


def test_decode_takes_torch_batches_and_refuses_wrong_shapes(codec):
    rng = np.random.default_rng(4)
    outputs = {k: torch.from_numpy(v) for k, v in _random_outputs(codec, rng, batch=3).items()}
    assert len(codec.decode_batch(outputs)) == 3
    with pytest.raises(CodecError, match="lack"):
        codec.decode_batch({k: v for k, v in outputs.items() if k != "angle"})
    with pytest.raises(CodecError, match="shape"):
        codec.decode_batch({**outputs, "unit": outputs["unit"][:, :3]})


def test_codec_survives_json_and_refuses_another_version(codec, samples):
    stored = json.loads(json.dumps(codec.to_dict()))
    again = ParameterCodec.from_dict(stored)
    for params in samples[:4]:
        first, second = codec.encode(params), again.encode(params)
        assert all(np.array_equal(first[k], second[k]) for k in first)
    outputs = _random_outputs(codec, np.random.default_rng(5), batch=4)
    assert codec.decode_batch(outputs) == again.decode_batch(outputs)
    with pytest.raises(CodecError, match=f"'sketchnet-codec/0'.*{CODEC_VERSION}"):
        ParameterCodec.from_dict({**stored, "version": "sketchnet-codec/0"})
    with pytest.raises(CodecError, match="malformed"):
        ParameterCodec.from_dict({k: v for k, v in stored.items() if k != "limits"})


def test_fit_refuses_no_dictionaries():
    with pytest.raises(CodecError, match="no dictionaries"):
        ParameterCodec.fit([])


# ------------------------------------------------------------------------------------------------ network
def test_output_shapes_at_a_tiny_width(codec):
    model = TreeSketchNet(codec.head_sizes, codec.n_species, in_channels=1, **TINY).eval()
    with torch.no_grad():
        outputs = model(torch.zeros(2, 1, 64, 64))
    assert list(outputs) == model.output_names == list(codec.output_sizes)
    assert {k: tuple(v.shape) for k, v in outputs.items()} == {k: (2, w) for k, w in codec.output_sizes.items()}
    colour = TreeSketchNet(codec.head_sizes, codec.n_species, in_channels=3, **TINY).eval()
    assert colour(torch.zeros(1, 3, 64, 64))["species"].shape == (1, codec.n_species)
    with pytest.raises(SketchNetError, match=r"\(batch, 1, height, width\).*\(1, 3, 64, 64\)"):
        model(torch.zeros(1, 3, 64, 64))


@pytest.mark.parametrize("setting", [{"in_channels": 2}, {"width": 0}, {"dropout": 1.0}, {"n_species": 0}])
def test_network_refuses_bad_settings(codec, setting):
    arguments = {"head_sizes": codec.head_sizes, "n_species": codec.n_species, **TINY, **setting}
    with pytest.raises(SketchNetError, match=next(iter(setting))):
        TreeSketchNet(**arguments)


def test_masked_values_do_not_change_the_loss(codec, samples):
    maple = next(s for s in samples if s["species"] == "maple")  # levels 2: levels 2 and 3 masked
    targets = codec.encode_batch([maple])
    outputs = {k: torch.from_numpy(v) for k, v in _random_outputs(codec, np.random.default_rng(6)).items()}
    loss, _ = sketchnet_loss(outputs, targets)
    masked = int(slot_names("angle").index("downAngle[3]"))
    used = int(slot_names("angle").index("downAngle[1]"))
    changed_target = {**targets, "angle": targets["angle"].clone()}
    changed_target["angle"][0, masked] = 123.0
    changed_output = {**outputs, "angle": outputs["angle"].clone()}
    changed_output["angle"][0, masked] = float("nan")
    assert float(sketchnet_loss(outputs, changed_target)[0]) == float(loss)
    assert float(sketchnet_loss(changed_output, targets)[0]) == float(loss)
    changed_target["angle"][0, used] = 123.0
    assert float(sketchnet_loss(outputs, changed_target)[0]) > float(loss)


def test_a_tiny_network_overfits_eight_samples(codec, samples):
    params = samples[:8]
    targets = codec.encode_batch(params)
    images = torch.rand(8, 1, 64, 64, generator=torch.Generator().manual_seed(0))
    torch.manual_seed(0)  # the weights' initialisation; the run is seeded either way
    model = TreeSketchNet(codec.head_sizes, codec.n_species, dropout=0.0, drop_path=0.0, **TINY)
    optimiser = torch.optim.Adam(model.parameters(), lr=3e-3)

    def regression(parts):
        return sum(parts[h] for h in REGRESSION_HEADS)

    history = []
    for _ in range(40):
        loss, parts = sketchnet_loss(model(images), targets)
        history.append((float(loss.detach()), regression(parts)))
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
    (first, first_regression), (last, last_regression) = history[0], history[-1]
    assert last < 0.1 * first and last_regression < 0.1 * first_regression


def test_stochastic_depth_and_dropout_follow_the_noise_generator(codec):
    model = TreeSketchNet(codec.head_sizes, codec.n_species, dropout=0.5, drop_path=0.5, **TINY).train()
    images = torch.rand(4, 1, 64, 64, generator=torch.Generator().manual_seed(1))
    runs = []
    for _ in range(2):
        model.set_noise_generator(torch.Generator().manual_seed(7))
        with torch.no_grad():
            runs.append(model(images)["angle"])
    assert torch.equal(runs[0], runs[1])


# ------------------------------------------------------------------------------------------------ metrics
def test_metrics_are_perfect_on_the_targets_and_lower_for_the_baseline(codec, samples):
    encoded = codec.encode_arrays(samples)
    targets = {k: torch.from_numpy(v) for k, v in encoded.items()}
    perfect = sketchnet_metrics({k: torch.from_numpy(v) for k, v in codec.as_outputs(encoded).items()}, targets)
    assert all(perfect[f"score_{h}"] == pytest.approx(100.0) for h in REGRESSION_HEADS)
    assert perfect["score_overall"] == pytest.approx(100.0)
    assert perfect["accuracy_categorical"] == 1.0 and perfect["accuracy_species"] == 1.0
    baseline = sketchnet_metrics({k: torch.from_numpy(v) for k, v in codec.baseline_outputs(len(samples)).items()},
                                 targets)
    assert baseline["score_overall"] < 95.0 and baseline["accuracy_species"] == pytest.approx(1 / len(samples))


def test_grown_tree_errors_are_zero_for_the_true_dictionary_and_grow_with_scale(samples):
    true = samples[:3]
    assert grown_tree_errors(true, true)["height_rel_error"] == 0.0
    taller = [{**d, "scale": d["scale"] * 1.5} for d in true]
    errors = grown_tree_errors(taller, true, seed=3)
    assert errors["n"] == 3 and errors["height_rel_error"] > 0.1 and errors["crown_radius_rel_error"] > 0.0


# ------------------------------------------------------------------------------------------------ ONNX
def test_onnx_export_matches_torch(codec, tmp_path):
    onnxruntime = pytest.importorskip("onnxruntime")
    torch.manual_seed(1)
    model = TreeSketchNet(codec.head_sizes, codec.n_species, **TINY)
    with torch.no_grad():  # running statistics that are not the initial ones
        model(torch.rand(4, 1, 64, 64, generator=torch.Generator().manual_seed(2)))
    path = export_onnx(model, tmp_path / "sketchnet.onnx", image_size=64)
    assert model.training  # export leaves the model's mode as it was
    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    session = onnxruntime.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    assert [o.name for o in session.get_outputs()] == model.output_names
    images = np.random.default_rng(3).random((3, 1, 64, 64), dtype=np.float32)
    got = session.run(None, {session.get_inputs()[0].name: images})
    model.eval()
    with torch.no_grad():
        expected = model(torch.from_numpy(images))
    for name, array in zip(model.output_names, got):
        np.testing.assert_allclose(array, expected[name].numpy(), atol=1e-4, rtol=0)
