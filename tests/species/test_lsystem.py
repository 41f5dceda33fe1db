"""Specification of the L-system growth model: dictionaries validated, skeletons valid, presets grow."""
import numpy as np
import pytest

import species
from species.errors import ParameterError
from species.lsystem.generator import SCHEMA, grow, validate
from species.lsystem.presets import PRESETS

BINARY = {"generator": "lsystem", "axiom": "X", "rules": ["X -> F[-X][+X]"], "iterations": 4, "angle": 30.0,
          "step": 0.5}


def test_grow_returns_a_skeleton_rooted_at_the_origin_growing_up():
    skeleton = grow(BINARY, np.random.default_rng(0))
    assert isinstance(skeleton, species.Skeleton)
    assert np.allclose(skeleton.positions[0], 0) and skeleton.positions[1, 2] > 0
    assert len(skeleton) == 1 + 15


def test_dispatch_through_species_grow():
    skeleton = species.grow(BINARY, np.random.default_rng(0))
    assert len(skeleton) == 16


def test_pipe_radii_never_grow_toward_the_tips():
    skeleton = grow(BINARY, np.random.default_rng(0))
    assert np.all(skeleton.radius[1:] <= skeleton.radius[skeleton.parent[1:]] + 1e-7)
    assert np.allclose(skeleton.radius[skeleton.tips], SCHEMA["tip_radius"].default)


def test_turtle_radii_follow_bang():
    params = {**BINARY, "axiom": "F!(0.5)F", "rules": [], "radii": "turtle", "width": 0.2}
    assert np.allclose(grow(params, np.random.default_rng(0)).radius, [0.1, 0.1, 0.05])


def test_tip_leaves_hang_from_tips():
    params = {**BINARY, "leaves_per_tip": 3}
    skeleton = grow(params, np.random.default_rng(0))
    assert skeleton.n_leaves == 3 * len(skeleton.tips)
    assert set(skeleton.leaf_node.tolist()) == set(skeleton.tips.tolist())


def test_leaf_size_sets_card_length():
    skeleton = grow({**BINARY, "leaf_size": 0.2}, np.random.default_rng(0))
    assert np.allclose(np.linalg.norm(skeleton.leaves[:, :3, 2], axis=1), 0.2, atol=1e-6)


def test_same_seed_same_skeleton_and_other_seed_differs_with_jitter():
    params = {**BINARY, "angle_jitter": 5.0, "step_jitter": 0.1}
    a, b = grow(params, np.random.default_rng(1)), grow(params, np.random.default_rng(1))
    c = grow(params, np.random.default_rng(2))
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.leaves, b.leaves)
    assert not np.allclose(a.positions, c.positions)


def test_twigs_option_grows_leafy_twigs_at_the_tips():
    plain = grow(BINARY, np.random.default_rng(0))
    twiggy = grow({**BINARY, "twigs": "alternate"}, np.random.default_rng(0))
    assert len(twiggy) == len(plain) + 9 * len(plain.tips) and twiggy.n_leaves == 5 * len(plain.tips)


@pytest.mark.parametrize("key, value", [
    ("iterations", -1), ("iterations", 2.5), ("iterations", "3"), ("angle", 400.0), ("step", 0.0),
    ("tropism", [0, 0]), ("tropism", [0, 0, -5]), ("rules", "X -> F"), ("radii", "thick"), ("twigs", "spiral"),
    ("leaves_per_tip", True), ("constants", {"r": "big"}), ("axiom", ""), ("colour", "green"),
])
def test_bad_value_is_rejected_naming_the_key(key, value):
    with pytest.raises(ParameterError) as caught:
        grow({**BINARY, key: value}, np.random.default_rng(0))
    assert caught.value.key == key and repr(key) in str(caught.value)


def test_missing_axiom_is_rejected():
    params = dict(BINARY)
    del params["axiom"]
    with pytest.raises(ParameterError, match="'axiom'"):
        validate(params)


def test_malformed_rule_is_rejected_naming_the_rule():
    with pytest.raises(ParameterError, match="X -> F\\[-X"):
        grow({**BINARY, "rules": ["X -> F[-X"]}, np.random.default_rng(0))


def test_grammar_that_draws_nothing_is_rejected():
    with pytest.raises(ParameterError, match="'axiom'"):
        grow({**BINARY, "iterations": 0}, np.random.default_rng(0))


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.name)
def test_every_preset_grows_a_valid_skeleton_with_two_seeds(preset):
    for seed in (0, 1):
        params = preset.sample(np.random.default_rng(seed))
        skeleton = grow(params, species.rng_for(params))
        assert 100 < len(skeleton) < 20_000
        assert np.all(skeleton.parent[1:] < np.arange(1, len(skeleton)))
        assert np.allclose(skeleton.positions[0], 0) and skeleton.height > 0.5
        assert skeleton.n_leaves > 0


def test_presets_are_registered_with_generator_lsystem():
    names = {p.name for p in PRESETS}
    assert len(names) == len(PRESETS) >= 5 and all(p.generator == "lsystem" for p in PRESETS)


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: p.name)
def test_every_preset_typical_member_grows(preset):
    params = preset.base_params()
    assert len(grow(params, species.rng_for(params))) > 100
