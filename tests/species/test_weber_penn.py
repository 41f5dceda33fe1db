"""Weber-Penn generator: Sapling dictionaries, invariants from the parameters, known answers, determinism."""
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import species
from fixtures.sapling import sapling_reference
from species.weber_penn.assembly import SkeletonAssemblyError, WeberPennTree, assemble
from species.weber_penn.generator import grow, grow_tree
from species.weber_penn.params import WeberPennParams
from species.weber_penn.schema import SAPLING_KEYS

SAPLING = Path(__file__).resolve().parents[3] / "shared" / "data" / "sapling"
# Sapling 0.3.4's own height and crown radius for the same dictionaries (the figures the benchmark prints beside).
SAPLING_REFERENCE = sapling_reference()["trees"]


def sapling_dict(name: str) -> dict:
    return json.loads((SAPLING / f"{name}.json").read_text())


def simple_params(**overrides) -> dict:
    """A small deterministic tree: no splits, no curvature variation, no realized draws left to chance."""
    params = {"levels": 2, "branches": [0, 50, 0, 0], "baseSize": 0.4, "scale": 10.0, "scaleV": 0.0,
              "length": [1.0, 0.3, 0.6, 0.45], "curve": [0, 0, 0, 0], "curveV1": [0, 0, 0, 0], "curveV2": [0, 0, 0, 0],
              "attractUp": [0, 0, 0, 0], "leaves": 0, "segSplits": [0, 0, 0, 0], "baseSplits": 0,
              "rLastAng": [0, 0, 0, 0], "splitAngleV1": [0, 0, 0, 0], "splitAngleV2": [0, 0, 0, 0],
              "rSplits2": 0.5, "scaleV0": 1.0, "leafScaleV": 1.0, "choiceNegPos1": 1, "choiceNegPos2": 1,
              "downAngleV": [0, 0, 0, 0]}
    params.update(overrides)
    return params


@pytest.mark.parametrize("name", sorted(SAPLING_REFERENCE))
def test_sapling_dictionary_grows_to_saplings_height_and_crown(name):
    params = sapling_dict(name)
    assert set(params) <= set(SAPLING_KEYS) and len(params) == 70
    skeleton = grow(params, np.random.default_rng(0))
    reference = SAPLING_REFERENCE[name]
    assert skeleton.height == pytest.approx(reference["height_m"], rel=0.15)
    assert skeleton.crown_radius == pytest.approx(reference["crown_radius_m"], rel=0.15)
    assert int(skeleton.order.max()) == params["levels"] - 1
    assert np.all(skeleton.order_counts() > 0), "every level has branches"
    assert skeleton.n_leaves > 0


def test_straight_trunk_height_is_scale_times_length():
    params = simple_params(levels=1, scale=7.0, scaleV=1.0, length=[0.8, 0.3, 0.6, 0.45])
    skeleton = grow(params, np.random.default_rng(0))
    trunk = skeleton.positions[skeleton.order == 0]
    assert trunk[:, 2].max() == pytest.approx((7.0 + 1.0) * 0.8, rel=1e-5)
    assert np.allclose(trunk[:, :2], 0, atol=1e-6)


def test_first_level_branch_count_follows_branches_and_base_size():
    # Sapling's rule: t = (a + 1) / 50 for a < 50, the lowest int(0.4 * 51) = 20 trimmed, t = 1 dropped, plus a
    # stem continuing from the trunk tip: 29 + 1 first-level branches.
    skeleton = grow(simple_params(), np.random.default_rng(0))
    assert skeleton.order_counts().tolist() == [1, 30]


def test_branches_start_above_base_size():
    skeleton = grow(simple_params(), np.random.default_rng(0))
    starts = skeleton.branch_starts[skeleton.order[skeleton.branch_starts] == 1]
    junction_heights = skeleton.positions[skeleton.parent[starts], 2]
    assert junction_heights.min() >= 0.4 * 10.0 - 1e-4


def test_radii_never_increase_along_a_branch():
    for name in SAPLING_REFERENCE:
        skeleton = grow(sapling_dict(name), np.random.default_rng(1))
        child = np.flatnonzero(skeleton.parent >= 0)
        same_branch = skeleton.branch_id[child] == skeleton.branch_id[skeleton.parent[child]]
        c = child[same_branch]
        assert np.all(skeleton.radius[c] <= skeleton.radius[skeleton.parent[c]] + 1e-6), name


def test_child_branches_are_thinner_than_their_parent_at_the_junction():
    skeleton = grow(sapling_dict("9_cherry_blossom_3"), np.random.default_rng(0))
    starts = skeleton.branch_starts[1:]
    assert np.all(skeleton.radius[starts] <= skeleton.radius[skeleton.parent[starts]] * 1.0001)


def test_leaves_hang_near_their_node_and_inside_the_crown():
    params = sapling_dict("0_acer_2")
    skeleton = grow(params, np.random.default_rng(0))
    origins = skeleton.leaves[:, :3, 3]
    longest_edge = skeleton.segment_lengths.max()
    assert np.all(np.linalg.norm(origins - skeleton.positions[skeleton.leaf_node], axis=1) <= longest_edge + 1e-5)
    leaf_size = params["leafScale"] * params["leafScaleV"] * (1 + params["leafScaleT"])
    node_reach = np.hypot(*skeleton.positions[:, :2].T).max()
    assert skeleton.crown_radius <= node_reach + 1.5 * leaf_size
    assert skeleton.height <= skeleton.positions[:, 2].max() + 1.5 * leaf_size


def test_number_of_leaves_follows_leaves_per_stem_for_negative_leaves():
    params = sapling_dict("9_cherry_blossom_3")  # leaves = -5: a fan of 5 at every last-level tip
    skeleton = grow(params, np.random.default_rng(0))
    last = skeleton.order == params["levels"] - 1
    assert skeleton.n_leaves == 5 * int((last & (skeleton.n_children == 0)).sum())


def test_same_dictionary_and_seed_give_identical_skeletons():
    params = sapling_dict("6_pine")
    a, b = grow(params, np.random.default_rng(7)), grow(params, np.random.default_rng(7))
    for name, array in a.to_arrays().items():
        assert np.array_equal(array, getattr(b, name)), name


def test_missing_realized_draws_are_taken_from_the_rng():
    params = {k: v for k, v in sapling_dict("0_acer_2").items() if k not in ("curveV1", "curveV2", "rLastAng")}
    a, b = grow(params, np.random.default_rng(1)), grow(params, np.random.default_rng(2))
    assert a.n_nodes != b.n_nodes or not np.allclose(a.positions, b.positions)


def test_pruning_keeps_branch_tips_inside_the_envelope():
    base = simple_params(branches=[0, 30, 0, 0], length=[1.0, 0.9, 0.6, 0.45], downAngle=[0, 80, 45, 45])
    free = grow({**base, "prune": False}, np.random.default_rng(0))
    pruned = grow({**base, "prune": True, "pruneWidth": 0.15, "pruneBase": 0.3, "pruneWidthPeak": 0.6,
                   "prunePowerHigh": 0.5, "prunePowerLow": 0.001, "pruneRatio": 1.0}, np.random.default_rng(0))
    assert pruned.crown_radius < free.crown_radius
    tips = pruned.tips[pruned.order[pruned.tips] == 1]
    reach = np.hypot(*pruned.positions[tips, :2].T)
    assert reach.max() <= 0.15 * 10.0 * 1.05  # envelope width at its peak, within the bisection tolerance


@pytest.mark.parametrize("key, value, fragment", [
    ("levelz", 2, "'levelz'"),
    ("levels", 5, "in [1, 4]"),
    ("levels", "3", "'levels' = '3'"),
    ("branches", [0, 10, 5], "list of 4 integers"),
    ("shape", "12", "one of [0, 1, 2, 3, 4, 5, 6, 7, 8, 10]"),
    ("shape", 9, "one of [0, 1, 2, 3, 4, 5, 6, 7, 8, 10]"),  # the pruning envelope is in no Sapling menu
    ("shapeS", 8, "one of [0, 1, 2, 3, 4, 5, 6, 7, 10]"),    # no custom profile for secondary branches
    ("leafDist", 8, "one of [0, 1, 2, 3, 4, 5, 6, 7, 10]"),
    ("leafShape", "round", "['rect', 'hex']"),
    ("horzLeaves", 1, "true or false"),
    ("ratio", float("nan"), "'ratio'"),
])
def test_bad_dictionaries_name_the_key_value_and_allowed_range(key, value, fragment):
    params = sapling_dict("0_acer_2")
    params[key] = value
    with pytest.raises(species.ParameterError) as info:
        species.grow(params, np.random.default_rng(0))
    assert fragment in str(info.value)
    assert info.value.key == key


def test_a_dictionary_without_generator_is_weber_penn():
    params = sapling_dict("3_palm_3")
    assert "generator" not in params
    assert isinstance(species.grow(params, np.random.default_rng(0)), species.Skeleton)


def test_runaway_splitting_raises_a_clear_error_instead_of_exhausting_memory(monkeypatch):
    params = simple_params(curveRes=[8, 30, 3, 1], segSplits=[0, 2.0, 0, 0], rSplits2=0.0, branches=[0, 10, 0, 0])
    with pytest.raises(species.TreeTooLargeError, match=r"level 1 would grow about [\d,]+ stems .*segSplits\[1\]"):
        grow(params, np.random.default_rng(0))
    # the in-growth check stays as a backstop behind the estimate
    monkeypatch.setattr("species.weber_penn.generator.check_tree_size", lambda params: None)
    with pytest.raises(species.TreefarmError, match=r"level 1 grew \d+ stems .*segSplits\[1\]"):
        grow(params, np.random.default_rng(0))


def test_the_parameter_object_names_each_levels_keys_and_is_frozen():
    source = sapling_dict("0_acer_2")
    params = WeberPennParams.from_dict(source, np.random.default_rng(0))
    for order, level in enumerate(params.stem_levels):
        assert level.curve_res == source["curveRes"][order]
        assert level.down_angle == source["downAngle"][order]
        assert level.branches == source["branches"][order]
    assert params.leaves.count == source["leaves"] and params.prune.enabled == source["prune"]
    assert params.tree_scale == pytest.approx(source["scale"] + source["scaleV"])
    np.testing.assert_allclose(params.draws.curve_variation, np.radians(source["curveV1"]))
    with pytest.raises(dataclasses.FrozenInstanceError):
        params.levels = 1
    with pytest.raises(ValueError):
        params.draws.curve_variation[0] = 0.0


def test_the_parameter_object_rejects_what_the_schema_rejects():
    with pytest.raises(species.ParameterError, match="'levels'"):
        WeberPennParams.from_dict({**sapling_dict("6_pine"), "levels": 9}, np.random.default_rng(0))


def test_growing_in_steps_gives_the_same_skeleton_as_grow():
    source = sapling_dict("6_pine")
    whole = grow(source, np.random.default_rng(3))
    rng = np.random.default_rng(3)
    stepped = assemble(grow_tree(WeberPennParams.from_dict(source, rng), rng))
    for name, array in whole.to_arrays().items():
        assert np.array_equal(array, getattr(stepped, name)), name


@pytest.mark.parametrize("spline, u", [(10_000, 0.0), (0, 200.0)], ids=["no such spline", "past its last node"])
def test_a_leaf_that_matches_no_node_is_an_error_naming_the_leaf_and_spline(spline, u):
    rng = np.random.default_rng(0)
    tree = grow_tree(WeberPennParams.from_dict(simple_params(leaves=6), rng), rng)
    assert len(tree.leaves) > 3
    leaf_spline, leaf_u = tree.leaf_spline.copy(), tree.leaf_u.copy()
    leaf_spline[3], leaf_u[3] = spline, u
    with pytest.raises(SkeletonAssemblyError, match=rf"leaf 3 .*spline {spline} .*no node at step {u:g}"):
        assemble(WeberPennTree(tree.levels, tree.leaves, leaf_spline, leaf_u))
    assert issubclass(SkeletonAssemblyError, species.TreefarmError)
