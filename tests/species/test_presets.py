"""Species presets: every preset samples valid dictionaries that grow, deterministically, from the dictionary alone."""
import json

import numpy as np
import pytest

import species
from species.weber_penn.schema import validate

WEBER_PENN = [p.name for p in species.list_presets("weber_penn")]


def test_library_has_the_tsn_species_and_classic_trees():
    names = set(WEBER_PENN)
    assert {"maple", "pine", "bonsai", "palm", "cherry"} <= names
    assert len(names) >= 12
    assert all(p.description and len(p.description.splitlines()) == 1 for p in species.list_presets())


@pytest.mark.parametrize("name", WEBER_PENN)
def test_preset_samples_valid_dictionaries_that_grow(name):
    for seed in range(3):
        params = species.sample(name, np.random.default_rng(seed))
        validate(params)
        skeleton = species.grow(params, species.rng_for(params))
        assert int(skeleton.order.max()) == params["levels"] - 1
        assert skeleton.height > 0.2 and skeleton.n_leaves > 0


def test_sampling_is_deterministic_and_seeds_differ():
    a = species.sample("black_oak", np.random.default_rng(5))
    b = species.sample("black_oak", np.random.default_rng(5))
    c = species.sample("black_oak", np.random.default_rng(6))
    assert a == b and a != c


def test_sampled_dictionary_records_sapling_draws_and_fixed_keys():
    preset = species.get_preset("pine")
    params = species.sample(preset, np.random.default_rng(0))
    for key in ("curveV1", "curveV2", "splitAngleV1", "splitAngleV2", "rLastAng", "choiceNegPos1",
                "scaleV", "scaleV0", "seed"):
        assert key in params
    assert "rSplits2" not in params  # one threshold for every split decision: left to the seed's rng
    for key in ("curve", "downAngle", "nrings" if "nrings" in preset.fixed else "levels"):
        if key in preset.fixed:
            assert params[key] == preset.fixed[key]


def test_dictionary_alone_rebuilds_the_tree_byte_identically():
    params = species.sample("maple", np.random.default_rng(3))
    reloaded = json.loads(json.dumps(params))
    first = species.build_mesh(species.grow(params, species.rng_for(params)), params).to_glb()
    second = species.build_mesh(species.grow(reloaded, species.rng_for(reloaded)), reloaded).to_glb()
    assert first == second


def test_unknown_preset_lists_the_known_ones():
    with pytest.raises(species.PresetError, match="known: .*maple"):
        species.sample("baobab", np.random.default_rng(0))


def test_range_specs_draw_scalars_and_lists():
    from species.presets import Choice, IntRange, Jitter, Uniform

    rng = np.random.default_rng(0)
    assert isinstance(Uniform(1.0, 2.0).draw(rng), float)
    assert len(Uniform([0, 0], [1, 2]).draw(rng)) == 2
    assert 3 <= IntRange(3, 5).draw(rng) <= 5
    assert Choice(("a", "b")).draw(rng) in ("a", "b")
    drawn = Jitter([10, 0], rel=0.25, integer=True).draw(rng)
    assert 7 <= drawn[0] <= 13 and drawn[1] == 0


@pytest.mark.parametrize("name", WEBER_PENN)
def test_preset_size_stays_bounded_over_many_seeds(name):
    nodes = [species.grow(p, species.rng_for(p)).n_nodes
             for p in (species.sample(name, np.random.default_rng(seed)) for seed in range(10, 22))]
    assert max(nodes) < 60_000, f"{name}: node counts {sorted(nodes)}"
    assert max(nodes) < 8 * np.median(nodes), f"{name}: a seed grows far more than the typical tree: {nodes}"
