"""Sapling's own preset files load as the add-on loads them, and `draws: ranges` draws their variation ranges as
Sapling does; TreeSketchNet's dictionaries keep reading as realized draws."""
from __future__ import annotations

import ast
import json
from pathlib import Path

import numpy as np
import pytest

import species
from species.errors import ParameterError
from species.weber_penn import (BLENDER_ONLY_KEYS, WeberPennParams, draws_semantics, load_sapling_preset, validate)
from species.weber_penn.params import RealizedDraws

SHARED = Path(__file__).resolve().parents[2].parent / "shared"
PRESETS = sorted((SHARED / "tools" / "sapling" / "add_curve_sapling" / "presets").glob("*.py"))
TSN = sorted((SHARED / "data" / "sapling").glob("*.json"))


def literal(path: Path) -> dict:
    text = path.read_text()
    return ast.literal_eval(text[text.index("{"):])


def test_the_shared_presets_and_dictionaries_are_there():
    assert len(PRESETS) == 5 and len(TSN) == 5


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_every_sapling_preset_file_loads_as_ranges_and_grows(path):
    preset = load_sapling_preset(path)
    assert preset.params["draws"] == "ranges" and draws_semantics(preset.params) == "ranges"
    assert set(preset.ignored) == set(literal(path)) & set(BLENDER_ONLY_KEYS) and len(preset.ignored) == 18
    skeleton, mesh = species.rebuild(preset.params)
    assert skeleton.height > 1.0 and mesh.n_faces > 100
    again = species.rebuild(species.sapling_preset(path))[0]  # the dictionary's seed decides every draw
    assert np.array_equal(again.positions, skeleton.positions)


def test_acer_values_outside_saplings_limits_are_clamped_as_blender_clamps_them():
    preset = load_sapling_preset(next(p for p in PRESETS if p.stem == "acer"))
    assert preset.clamped["baseSize_s"] == (4.0, 1.0) and preset.clamped["rootFlare"] == (0.6, 1.0)
    assert preset.clamped["baseSplits"] == (-2, 0) and preset.params["curveRes"] == [6, 5, 3, 1]


def test_a_preset_as_json_or_as_settings_assignment_reads_as_the_py_file(tmp_path):
    path = PRESETS[0]
    as_json = tmp_path / "p.json"
    as_json.write_text(json.dumps(literal(path)))
    assigned = tmp_path / "q.py"
    assigned.write_text("settings = " + repr(literal(path)) + "\n")
    expected = load_sapling_preset(path).params
    assert load_sapling_preset(as_json).params == expected == load_sapling_preset(assigned).params


@pytest.mark.parametrize("text, named", [
    ("import os\nos.system('echo hi')\n", "literal values"),
    ("import os\n", "settings dict"),
    ("{'levels': __import__('os').getpid()}", "literal values"),
    ("{'levels': 3", "syntax error at line 1"),
    ("[1, 2, 3]", "a dict of Sapling settings"),
])
def test_a_preset_file_is_never_run_and_a_bad_one_names_what_is_wrong(tmp_path, text, named):
    path = tmp_path / "bad.py"
    path.write_text(text)
    with pytest.raises(ParameterError, match=named):
        load_sapling_preset(path)


@pytest.mark.parametrize("path", TSN, ids=lambda p: p.stem)
def test_treesketchnet_dictionaries_still_read_as_realized_draws(path):
    params = json.loads(path.read_text())
    assert draws_semantics(params) == "realized" and validate(params)["draws"] == "realized"


@pytest.mark.parametrize("params, key", [
    ({"curveV": [0, 10, 0, 0], "curveV1": [0, 5, 0, 0]}, "curveV1"),
    ({"draws": "realized", "splitAngleV": [0, 5, 0, 0]}, "splitAngleV"),
    ({"af1": 1.0, "rLastAng": [0, 0, 0, 0]}, "rLastAng"),
    ({"draws": "sampled"}, "draws"),
    ({"draws": "ranges", "scaleV0": 1.5}, "scaleV0"),
    ({"draws": "ranges", "scaleV": -2.0}, "scaleV"),
])
def test_a_dictionary_mixing_the_two_readings_is_refused_naming_the_key(params, key):
    with pytest.raises(ParameterError) as raised:
        validate(params)
    assert raised.value.key == key


def test_per_tree_ranges_are_drawn_uniformly_within_saplings_bounds():
    validated = validate({"draws": "ranges", "scale": 10.0, "scaleV": 3.0, "scaleV0": 0.2})
    draws = [RealizedDraws.from_validated(validated, np.random.default_rng(seed)) for seed in range(400)]
    offsets = np.array([d.scale_offset for d in draws])
    factors = np.array([d.trunk_radius_factor for d in draws])
    assert offsets.min() >= -3.0 and offsets.max() <= 3.0 and offsets.std() == pytest.approx(3.0 / 3**0.5, rel=0.15)
    assert factors.min() >= 0.8 and factors.max() <= 1.2 and abs(factors.mean() - 1.0) < 0.02
    tree_scales = [WeberPennParams.from_validated(validated, np.random.default_rng(s)).tree_scale for s in range(3)]
    assert len(set(tree_scales)) == 3


def _leaf_sizes(params: dict, seed: int) -> np.ndarray:
    from species.weber_penn import grow_tree

    tree = grow_tree(WeberPennParams.from_dict(params, np.random.default_rng(seed)), np.random.default_rng(seed))
    return np.linalg.norm(tree.leaves[:, :3, 1], axis=1)


def test_leaf_scale_range_varies_each_leaf_and_a_realized_factor_scales_them_all():
    base = {"levels": 2, "branches": [0, 12, 0, 0], "leaves": 20, "leafScale": 0.2, "leafScaleT": 0.0, "seed": 1}
    ranged = _leaf_sizes({**base, "draws": "ranges", "leafScaleV": 0.5}, 1)
    assert ranged.min() >= 0.2 * 0.5 - 1e-9 and ranged.max() <= 0.2 * 1.5 + 1e-9 and ranged.std() > 0.03
    realized = _leaf_sizes({**base, "leafScaleV": 0.5}, 1)
    assert np.allclose(realized, 0.1)


def test_curve_and_split_ranges_make_stems_differ_by_seed_and_nothing_else_does():
    base = {"draws": "ranges", "levels": 2, "branches": [0, 10, 0, 0], "segSplits": [0.6, 0.5, 0, 0],
            "splitAngle": [20, 20, 0, 0], "rotateV": [0, 0, 0, 0], "downAngleV": [0, 0, 0, 0], "lengthV": [0] * 4,
            "leaves": 0, "seed": 5}

    def positions(params: dict, seed: int) -> np.ndarray:
        return species.grow(params, np.random.default_rng(seed)).positions

    same = positions({**base, "curveV": [0, 0, 0, 0]}, 1)
    assert np.array_equal(same, positions({**base, "curveV": [0, 0, 0, 0]}, 1))
    curved = [positions({**base, "curveV": [60, 60, 0, 0]}, seed) for seed in (1, 2)]
    assert curved[0].shape != curved[1].shape or not np.allclose(curved[0], curved[1])


def test_a_sapling_dictionary_that_leaves_keys_out_gets_saplings_defaults_and_ours_keeps_ours():
    from species.weber_penn import SCHEMA
    from species.weber_penn.sapling_keys import SAPLING_DEFAULTS

    ranged, realized = validate({"draws": "ranges"}), validate({})
    assert all(ranged[key] == value for key, value in SAPLING_DEFAULTS.items())
    assert ranged["splitByLen"] is False and ranged["curveV"] == [20, 50, 75, 0] and ranged["scaleV"] == 3.0
    # Both readings take Sapling's splitByLen (off); our presets set it on, as they were shaped with it.
    assert realized["splitByLen"] is SCHEMA["splitByLen"].default is False and "curveV" not in realized
    assert species.sample("maple", np.random.default_rng(0))["splitByLen"] is True


def test_negative_variation_ranges_grow_as_saplings_symmetric_draws():
    base = {"draws": "ranges", "levels": 2, "branches": [0, 8, 0, 0], "segSplits": [0.8, 0.4, 0, 0],
            "splitAngle": [20, 20, 0, 0], "leaves": 0, "seed": 3, "curveV": [-40, -30, 0, 0]}
    flipped = species.grow({**base, "rotateV": [-10, 0, 0, 0], "splitAngleV": [-5, -5, 0, 0]},
                           np.random.default_rng(3))
    plain = species.grow({**base, "rotateV": [10, 0, 0, 0], "splitAngleV": [5, 5, 0, 0]}, np.random.default_rng(3))
    assert np.array_equal(flipped.positions, plain.positions)


# Older and result presets the add-on loads: it sets every key and reads only its own (issue 48, point 1).
ASPEN = next((p for p in PRESETS if p.stem == "quaking_aspen"), None)
STORED_DRAWS = {"curveV1": [1.0, 2.0, 0.0, 0.0], "curveV2": [0.5, 1.0, 0.0, 0.0], "rLastAng": [10, 20, 30, 40]}


def _preset_file(tmp_path: Path, name: str, extra: dict, as_json: bool = False) -> Path:
    settings = {**literal(ASPEN), **extra}
    path = tmp_path / name
    path.write_text(json.dumps(settings) if as_json else repr(settings))
    return path


@pytest.mark.parametrize("extra, reason", [
    ({"startCurv": 0.0}, "no longer defines"),
    ({"windSpeed": 2.0, "windGust": 0.0}, "older wind system"),
    ({"lenght": 3}, "never reads it"),
])
def test_a_preset_with_keys_the_add_on_does_not_define_grows_as_without_them(tmp_path, extra, reason):
    preset = load_sapling_preset(_preset_file(tmp_path, "old.py", extra))
    assert set(extra) <= set(preset.ignored) and all(reason in preset.ignored[key] for key in extra)
    assert not set(extra) & set(validate(preset.params))
    grown = species.rebuild(preset.params)[0]
    plain = species.rebuild(load_sapling_preset(ASPEN).params)[0]
    assert np.array_equal(grown.positions, plain.positions)


@pytest.mark.parametrize("as_json", [False, True], ids=["py", "json"])
def test_a_preset_with_stored_draws_beside_ranges_grows_from_the_ranges(tmp_path, as_json):
    path = _preset_file(tmp_path, "result.json" if as_json else "result.py", STORED_DRAWS, as_json)
    preset = load_sapling_preset(path)
    assert preset.params["draws"] == "ranges" and not set(STORED_DRAWS) & set(preset.params)
    assert all("grown from Sapling's ranges" in preset.ignored[key] for key in STORED_DRAWS)
    assert preset.params == load_sapling_preset(ASPEN).params


def test_a_json_preset_that_says_realized_keeps_its_stored_draws_and_drops_the_ranges(tmp_path):
    preset = load_sapling_preset(_preset_file(tmp_path, "r.json", {**STORED_DRAWS, "draws": "realized"}, True))
    assert preset.params["draws"] == "realized" and preset.params["curveV1"] == STORED_DRAWS["curveV1"]
    assert {"curveV", "splitAngleV"} <= set(preset.ignored) and "curveV" not in preset.params
    assert preset.params["scaleV0"] == literal(ASPEN)["scaleV0"]  # a drawn factor: not clamped as a range
    draws = WeberPennParams.from_dict(preset.params, np.random.default_rng(0)).draws
    assert np.allclose(np.degrees(draws.curve_variation), STORED_DRAWS["curveV1"]) and draws.ranges is None


@pytest.mark.parametrize("params, key", [
    ({"startCurv": 0.0, "levels": "three"}, "levels"),
    ({"windSpeed": 2.0, "scale": -4}, "scale"),
])
def test_a_known_key_with_a_bad_value_beside_an_old_key_is_still_refused(tmp_path, params, key):
    path = tmp_path / "bad.py"
    path.write_text(repr(params))
    with pytest.raises(ParameterError) as raised:
        validate(load_sapling_preset(path).params)
    assert raised.value.key == key


def test_an_old_sapling_key_is_ignored_in_a_dictionary_too_and_an_unknown_one_refused():
    assert validate({"levels": 2, "startCurv": 0.0}) == validate({"levels": 2, "windSpeed": 2.0, "windGust": 0})
    with pytest.raises(ParameterError, match="known Weber-Penn key"):
        validate({"levels": 2, "lenght": 3})


# A dictionary that describes no tree is refused rather than grown as the default tree (issue 48, point 7).
@pytest.mark.parametrize("params, generator", [
    ({}, "weber_penn"),
    ({"generator": "weber_penn"}, "weber_penn"),
    ({"species": "maple", "seed": 3, "draws": "ranges"}, "weber_penn"),
    ({"wind": 1.0, "startCurv": 0.0}, "weber_penn"),
    ({"generator": "colonization"}, "colonization"),
])
def test_a_dictionary_with_no_key_that_describes_a_tree_is_refused(params, generator):
    with pytest.raises(ParameterError, match=f"at least one {generator} parameter") as raised:
        species.grow(params, np.random.default_rng(0))
    assert raised.value.key == "params"


def test_one_describing_key_is_enough_and_validate_still_gives_the_defaults():
    assert species.grow({"levels": 1}, np.random.default_rng(0)).n_nodes > 1
    assert validate({})["levels"] == validate({"seed": 3})["levels"]


def test_a_preset_whose_every_key_is_ignored_is_refused_naming_its_keys(tmp_path):
    path = tmp_path / "nothing.py"
    path.write_text(repr({"lenght": 3, "windSpeed": 2.0, "gust": 1.0}))
    with pytest.raises(ParameterError, match="beside generator, species, seed, draws, name, lenght, windSpeed, gust"):
        load_sapling_preset(path)
