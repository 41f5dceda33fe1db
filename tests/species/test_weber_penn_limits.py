"""The Weber-Penn size estimate: exploding dictionaries are refused before growth, from their parameters; the
estimate bounds what presets, TreeSketchNet dictionaries and their split- and leaf-heavy variants actually grow,
within twice of it, and refuses none of them."""
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


def _sample(preset: str, seed: int, **changes) -> dict:
    """A preset's sample with keys replaced; a {level: value} dict replaces entries of a per-level list."""
    params = species.sample(preset, np.random.default_rng(seed))
    for key, change in changes.items():
        params[key] = ([change.get(level, value) for level, value in enumerate(params[key])]
                       if isinstance(change, dict) else change)
    return params


def _grown(params: dict):
    rng = species.rng_for(params)
    return generator.grow_tree(WeberPennParams.from_dict(params, rng), rng)


# Trees that grew before the estimate refused them (issue 20), and split- and leaf-heavy variants.
VARIANTS = {
    "black_oak segSplits[1]=1.5": ("black_oak", {"segSplits": {1: 1.5}}),
    "pine leaves=10000": ("pine", {"leaves": 10000}),
    "sassafras segSplits .6": ("sassafras", {"segSplits": {0: 0.6, 1: 0.6, 2: 0.6}}),
    "black_oak baseSplits=8": ("black_oak", {"baseSplits": 8}),
    "cherry leaves=-60": ("cherry", {"leaves": -60}),
}


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


@pytest.mark.parametrize("preset,changes", [VARIANTS["black_oak segSplits[1]=1.5"], VARIANTS["pine leaves=10000"]],
                         ids=["black_oak segSplits[1]=1.5", "pine leaves=10000"])
def test_extreme_variants_that_grew_before_pass_the_estimate_and_grow(preset, changes):
    params = _sample(preset, 0, **changes)
    check_tree_size(WeberPennParams.from_dict(params, np.random.default_rng(0)))
    assert species.grow(params, species.rng_for(params)).n_nodes > 0


@pytest.mark.parametrize("name,seed,changes", [
    *((preset, seed, {}) for preset in ("black_oak", "cherry", "sassafras", "bonsai", "maple") for seed in (0, 1)),
    *((name, 0, VARIANTS[name][1]) for name in VARIANTS if name != "pine leaves=10000"),
])
def test_estimate_is_within_twice_what_grows(name, seed, changes):
    params = _sample(VARIANTS[name][0] if name in VARIANTS else name, seed, **changes)
    tree = _grown(params)
    estimate = _estimate(params)
    largest = int(np.argmax([level.n_splines for level in tree.levels]))
    real_nodes = sum(level.n_splines * (level.n_segments + 1) for level in tree.levels)
    assert 1.0 <= estimate.splines[largest] / tree.levels[largest].n_splines <= 2.0
    assert 1.0 <= estimate.total_nodes / real_nodes <= 2.0
    assert 1.0 <= estimate.leaves / len(tree.leaves) <= 2.0


@pytest.mark.parametrize("params", [
    {"levels": 4, "branches": [0, 2000, 2000, 2000]},
    {"levels": 4, "branches": [0, 2000, 2000, 2000], "curveRes": [64, 64, 64, 64], "leaves": 10000},
    {"levels": 4, "branches": [0, 2000, 2000, 2000], "curveRes": [64, 64, 64, 64], "segSplits": [3, 3, 3, 3],
     "baseSplits": 10, "leaves": 10000},
], ids=["branches", "branches-curveRes-leaves", "everything-at-its-top"])
def test_explosions_are_refused_within_a_second(params):
    read = WeberPennParams.from_dict(params, np.random.default_rng(0))
    started = time.perf_counter()
    with pytest.raises(species.TreeTooLargeError, match="limit"):
        check_tree_size(read)
    assert time.perf_counter() - started < 1.0
