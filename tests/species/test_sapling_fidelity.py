"""The Sapling differential comparison (`fixtures.sapling`, printed by benchmarks/bench_sapling_fidelity.py) on
its committed Sapling figures: the reference covers every dictionary, treefarm's side grows comparable rows, and
the comparison is sound."""
import json

import numpy as np
import pytest

import species
from fixtures import sapling as fidelity

REFERENCE = json.loads(fidelity.FIDELITY_REFERENCE.read_text())
# Small trees of each kind, so that treefarm's side of the test grows in seconds.
FEW = ("sapling:quaking_aspen", "tsn:3_palm_3", "ours:palm_0")
FEW_SEEDS = 4


@pytest.fixture(scope="module")
def dictionaries():
    return {h.name: h for h in fidelity.harness_dictionaries()}


@pytest.fixture(scope="module")
def few_records(dictionaries):
    ours = {name: [{"seed": s, **fidelity.treefarm_figures(dictionaries[name].treefarm, s)}
                   for s in range(FEW_SEEDS)] for name in FEW}
    sapling = {name: REFERENCE["trees"][name] for name in FEW}
    return ours, fidelity.compare(ours, sapling, np.random.default_rng(0))


def test_reference_holds_every_harness_dictionary_over_at_least_24_seeds(dictionaries):
    assert len(dictionaries) >= 40
    assert sum(h.kind == "our_preset" for h in dictionaries.values()) >= 30
    assert REFERENCE["seeds"] >= 24 and {"blender", "sapling"} <= set(REFERENCE["versions"])
    assert fidelity.stale_dictionaries(REFERENCE, list(dictionaries.values())) == []
    for name in dictionaries:
        rows = REFERENCE["trees"][name]
        assert sorted(r["seed"] for r in rows) == list(range(REFERENCE["seeds"])), name


def test_reference_rows_are_finite_positive_figures():
    for name, rows in REFERENCE["trees"].items():
        for row in rows:
            if "error" in row:
                continue
            assert row["seconds"] > 0 and row["bark_height_m"] > 0 and row["crown_radius_m"] > 0, (name, row)
            assert row["stems_per_level"][0] >= 1 and min(row["stems_per_level"]) >= 0, (name, row)
            assert row["leaves"] >= 0


def test_our_preset_dictionaries_carry_ranges_and_no_realized_draws(dictionaries):
    for h in dictionaries.values():
        if h.kind == "our_preset":
            assert h.treefarm["draws"] == "ranges"
            assert not set(fidelity.REALIZED_ONLY_KEYS) & set(h.treefarm)
            assert len(h.treefarm["curveV"]) == 4 and len(h.treefarm["splitAngleV"]) == 4


def test_preset_ranges_read_the_half_widths_our_maple_draws_from():
    maple = species.get_preset("maple")
    ranges = fidelity.preset_ranges(maple)
    assert ranges["scaleV"] == pytest.approx(0.8)
    assert ranges["scaleV0"] == pytest.approx(0.1) and ranges["leafScaleV"] == pytest.approx(0.15)
    assert ranges["curveV"] == [2, 10, 20, 0] and ranges["splitAngleV"] == [4, 4, 4, 0]


def test_treesketchnet_dictionary_reaches_sapling_with_its_realized_scales():
    params = {"scale": 5.0, "scaleV": 0.5, "scale0": 1.0, "scaleV0": 0.9, "leafScale": 0.4, "leafScaleV": 0.5}
    given = fidelity.realized_for_sapling(params)
    assert given["scale"] == 5.5 and given["scale0"] == 0.9 and given["leafScale"] == 0.2
    assert given["scaleV"] == given["scaleV0"] == given["leafScaleV"] == 0.0


def test_treefarm_rows_measure_what_the_sapling_rows_measure(few_records):
    ours, _ = few_records
    for name, rows in ours.items():
        sapling_row = REFERENCE["trees"][name][0]
        for row in rows:
            assert "error" not in row and set(row) == set(sapling_row), (name, row)
            assert np.isfinite([row["seconds"], row["bark_height_m"], row["crown_radius_m"]]).all()


def test_comparison_has_every_measure_with_its_point_inside_its_interval(few_records):
    _, records = few_records
    for name in FEW:
        mine = [r for r in records if r["name"] == name]
        measures = [r["measure"] for r in mine]
        assert measures[:2] == ["bark_height_m", "crown_radius_m"] and measures[-1] == "leaves"
        assert measures[2:-1] == [f"stems_L{k}" for k in range(len(measures) - 3)]
        for r in mine:
            assert r["n"] == (FEW_SEEDS, REFERENCE["seeds"]) and not r["missing"]
            assert np.isfinite([r["ratio"], r["lo"], r["hi"], r["score"]]).all(), r
            assert r["lo"] <= r["ratio"] <= r["hi"], r
            assert r["flag"] == (r["score"] > 0)


def test_bootstrap_of_a_sample_against_its_double_is_a_half():
    sample = np.arange(1.0, 26.0)
    point, lo, hi = fidelity.bootstrap_ratio(sample, 2 * sample, np.random.default_rng(0))
    assert point == 0.5 and lo < 0.5 < hi
    # Constant samples leave no noise: the interval is the point.
    assert fidelity.bootstrap_ratio(np.full(9, 3.0), np.full(7, 2.0), np.random.default_rng(1)) == (1.5, 1.5, 1.5)


def test_bootstrap_interval_narrows_as_samples_grow():
    rng = np.random.default_rng(2)
    small, large = rng.normal(10, 1, (2, 24)), rng.normal(10, 1, (2, 960))
    _, lo_s, hi_s = fidelity.bootstrap_ratio(small[0], small[1], np.random.default_rng(3))
    _, lo_l, hi_l = fidelity.bootstrap_ratio(large[0], large[1], np.random.default_rng(3))
    assert hi_l - lo_l < (hi_s - lo_s) / 3
    assert lo_l < 1 < hi_l


def test_zero_counts_on_both_sides_are_the_same():
    assert fidelity.bootstrap_ratio(np.zeros(5), np.zeros(5), np.random.default_rng(0)) == (1.0, 1.0, 1.0)


def test_a_difference_is_flagged_only_when_the_interval_leaves_the_band():
    assert fidelity.outside_band(0.95, 1.3, 0.10) == 0.0
    assert fidelity.outside_band(1.2, 1.3, 0.10) == pytest.approx(np.log(1.2 / 1.1))
    assert fidelity.outside_band(0.5, 0.8, 0.10) == pytest.approx(np.log(0.9 / 0.8))


# Sapling's own presets, TreeSketchNet dictionaries and dictionaries from our presets that once differed in stems
# (splitByLen's default, a stored rSplits2) or crashed (a negative rotateV range): they must stay within the bands,
# outside the bootstrap noise.
HELD = ("sapling:acer", "sapling:douglas_fir", "sapling:quaking_aspen", "sapling:weeping_willow",
        "sapling:white_birch", "tsn:0_acer_2", "tsn:6_pine", "tsn:12_bonsai", "ours:bonsai_0", "ours:maple_0",
        "ours:pine_0", "ours:sassafras_1", "ours:black_oak_0", "ours:weeping_willow_0")


@pytest.mark.slow
def test_sapling_presets_and_our_ranges_grow_within_the_bands_of_sapling(dictionaries):
    names = [name for name in HELD if name in REFERENCE["trees"]]
    assert len(names) == len(HELD)
    ours = {name: [{"seed": s, **fidelity.treefarm_figures(dictionaries[name].treefarm, s)}
                   for s in range(fidelity.N_SEEDS)] for name in names}
    records = fidelity.compare(ours, {name: REFERENCE["trees"][name] for name in names}, np.random.default_rng(0))
    flagged = [f"{r['name']} {r['measure']} {r.get('ratio', float('nan')):.3f}" for r in records if r["flag"]]
    assert not flagged, flagged
