"""The Weber-Penn size estimate: exploding dictionaries are refused before growth, from their parameters; the
estimate bounds what presets and TreeSketchNet dictionaries actually grow, and refuses none of them."""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest

import species
from species.weber_penn import generator, size_estimate
from species.weber_penn.params import WeberPennParams
from species.weber_penn.size_estimate import check_tree_size, estimate_size

SAPLING_DIR = Path("/work/shared/data/sapling")
WEBER_PENN_PRESETS = [preset for preset in species.list_presets() if preset.generator == "weber_penn"]


def _dictionaries() -> list[tuple[str, dict]]:
    dictionaries = [(path.stem, json.loads(path.read_text())) for path in sorted(SAPLING_DIR.glob("*.json"))]
    dictionaries += [(preset.name, species.sample(preset, np.random.default_rng(1))) for preset in WEBER_PENN_PRESETS]
    return dictionaries


def _estimate(params: dict):
    return estimate_size(WeberPennParams.from_dict(params, np.random.default_rng(0)))


def test_exploding_branches_are_refused_at_once_naming_branches():
    started = time.perf_counter()
    with pytest.raises(species.TreeTooLargeError, match=r"branches\[1\] = 2000 .* branches\[2\] = 2000"):
        species.grow({"levels": 4, "branches": [0, 2000, 2000, 2000]}, np.random.default_rng(0))
    assert time.perf_counter() - started < 1.0


def test_exploding_leaves_are_refused_naming_leaves():
    params = {"levels": 3, "branches": [0, 2000, 200, 0], "leaves": 10000}
    with pytest.raises(species.TreeTooLargeError, match="leaves = 10000 per last-level stem"):
        check_tree_size(WeberPennParams.from_dict(params, np.random.default_rng(0)))


def test_exploding_splits_are_refused_naming_seg_splits():
    params = {"levels": 2, "branches": [0, 50, 0, 0], "curveRes": [8, 40, 3, 1], "segSplits": [0, 2, 0, 0]}
    with pytest.raises(species.TreeTooLargeError, match=r"segSplits\[1\] = 2.0 over curveRes\[1\] = 40"):
        species.grow(params, np.random.default_rng(0))


@pytest.mark.parametrize("name,params", _dictionaries(), ids=[name for name, _ in _dictionaries()])
def test_estimate_bounds_the_grown_tree(name, params):
    rng = species.rng_for(params)
    tree = generator.grow_tree(WeberPennParams.from_dict(params, rng), rng)
    estimate = _estimate(params)
    assert len(estimate.splines) >= len(tree.levels)
    for order, level in enumerate(tree.levels):
        assert level.n_splines <= estimate.splines[order], (name, order)
        assert level.family.max() + 1 <= estimate.stems[order], (name, order)
    assert len(tree.leaves) <= estimate.leaves


@pytest.mark.parametrize("preset", WEBER_PENN_PRESETS, ids=[preset.name for preset in WEBER_PENN_PRESETS])
def test_no_sampled_preset_is_refused(preset):
    for seed in range(200):
        check_tree_size(WeberPennParams.from_dict(species.sample(preset, np.random.default_rng(seed)),
                                                  np.random.default_rng(0)))


def test_a_tree_at_the_limit_grows_and_one_stem_over_is_refused(monkeypatch):
    params = {"levels": 3, "branches": [0, 30, 8, 0], "leaves": 0, "segSplits": [0, 0.3, 0, 0]}
    largest = max(_estimate(params).splines)
    monkeypatch.setattr(size_estimate, "MAX_ESTIMATED_STEMS_PER_LEVEL", int(np.ceil(largest)))
    assert species.grow(params, np.random.default_rng(0)).n_nodes > 0
    monkeypatch.setattr(size_estimate, "MAX_ESTIMATED_STEMS_PER_LEVEL", int(np.ceil(largest)) - 1)
    with pytest.raises(species.TreeTooLargeError, match="limit"):
        species.grow(params, np.random.default_rng(0))
