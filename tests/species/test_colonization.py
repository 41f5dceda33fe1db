"""Specification of self-organizing growth (species.colonization and its growth spaces, allocation, steering)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import species
from species.colonization.allocation import allocate, jump_tables, path_products, subtree_sums
from species.colonization.generator import Colonizer, bole_guide, seed_from_guide, crown_space, grow, grow_in_space
from species.colonization.params import at_iteration, validate
from species.errors import ParameterError
from species.colonization.growth_space import (DepthMapCrown, MeshSpace, PointSpace, SuperquadricLobe, VoxelSpace,
                                  profile_crown)
from species.colonization.shadow import ShadowGrid
from species.skeleton import Skeleton
from species.colonization.steering import MarkerSteering

IL = 0.1
SMALL = {"generator": "colonization", "crown_radius": 8.0, "crown_height": 12.0, "crown_base": 3.0,
         "marker_density": 2.0, "max_markers": 6000, "iterations": 20}


def _colonizer(params: dict, seed: int = 0) -> Colonizer:
    p = validate(params)
    rng = np.random.default_rng(seed)
    space = crown_space(p, rng)
    return Colonizer(p, rng, space, IL, seed_from_guide(bole_guide(p, rng, IL), "tips", rng, p))


def _sphere_space(radius: float = 0.8, centre_z: float = 0.9) -> SuperquadricLobe:
    return SuperquadricLobe((0.0, 0.0, centre_z), (radius, radius, radius), 2.0)


# ---------------------------------------------------------------- space colonization invariants
def test_markers_inside_occupancy_zones_are_gone_after_every_step():
    colonizer = _colonizer(SMALL)
    rho = SMALL.get("occupancy_radius", 2.0) * IL
    steps = 0
    while steps < 12 and len(colonizer.buds["host"]):
        colonizer.step()
        steps += 1
        distance, _ = cKDTree(colonizer.node_positions).query(colonizer.markers_alive, k=1)
        assert distance.min() >= rho * (1 - 1e-9)
    assert colonizer.n_nodes > 100  # it really grew


def test_markers_are_consumed_as_the_crown_fills():
    colonizer = _colonizer(SMALL)
    before = colonizer.marker_alive.sum()
    colonizer.run()
    assert colonizer.marker_alive.sum() < 0.5 * before


@pytest.mark.parametrize("space_kind", ["ellipsoid", "mesh", "voxels", "points", "depth_maps"])
def test_every_grown_node_lies_inside_the_growth_space(space_kind):
    lobe = _sphere_space()
    if space_kind == "ellipsoid":
        space = lobe
    elif space_kind == "mesh":
        space = MeshSpace(lobe.to_mesh(3))
    elif space_kind == "voxels":
        grid = np.indices((16, 16, 16)).reshape(3, -1).T
        centres = (grid + 0.5) * 0.1 + np.array([-0.8, -0.8, 0.1])
        space = VoxelSpace(lobe.contains(centres).reshape(16, 16, 16), (-0.8, -0.8, 0.1), 0.1)
    elif space_kind == "points":
        space = PointSpace(lobe.sample_markers(3000, 400, np.random.default_rng(5)), 0.15)
    else:
        x, z = np.meshgrid(np.linspace(-1, 1, 64), np.linspace(1.7, 0.1, 64))
        half = np.sqrt(np.clip(0.64 - x ** 2 - (z - 0.9) ** 2, 0, None))
        front = np.where(half > 0, 0.5 - half / 2, 1.0)
        back = np.where(half > 0, 0.5 + half / 2, 1.0)
        space = DepthMapCrown(front, back, extent=(-1, 1, 0.1, 1.7), depth_range=(-1, 1))
    params = {**SMALL, "crown_base": 1.0}
    rng = np.random.default_rng(3)
    bole = bole_guide(validate(params), rng, IL)
    skeleton = grow_in_space(params, rng, space=space, guide=bole, guide_buds="tips")
    grown = skeleton.positions[len(bole):]
    assert len(grown) > 30
    assert space.contains(grown).all()


def test_mesh_space_agrees_with_the_analytic_lobe_it_was_made_from():
    lobe = SuperquadricLobe((0.1, -0.2, 1.0), (0.9, 0.6, 0.5), 3.0, yaw=0.4)
    mesh_space = MeshSpace(lobe.to_mesh(4))
    points = np.random.default_rng(0).uniform(lobe.bounds[0], lobe.bounds[1], (20000, 3))
    agreement = (mesh_space.contains(points) == lobe.contains(points)).mean()
    assert agreement > 0.97


def test_depth_map_crown_from_a_silhouette_holds_the_points_between_front_and_back():
    silhouette = np.zeros((4, 4, 3))
    silhouette[1:3, 1:3] = (0.25, 0.5, 1.0)  # front at 0.25, gap 0.5: y from -0.5 to 0.5 for depth range (-1, 1)
    crown = DepthMapCrown.from_silhouette(silhouette, extent=(-2, 2, 0, 4), depth_range=(-1, 1))
    inside = crown.contains(np.array([[0.0, 0.0, 2.0], [0.0, 0.45, 2.0], [0.0, 0.6, 2.0], [1.5, 0.0, 2.0]]))
    assert inside.tolist() == [True, True, False, False]


def test_open_mesh_is_rejected_as_a_growth_space():
    mesh = _sphere_space().to_mesh(2)
    with pytest.raises(species.TreefarmError, match="not closed"):
        MeshSpace(vertices=mesh.vertices, faces=mesh.faces[1:])


def test_markers_fill_the_space_at_the_asked_density():
    space = _sphere_space(radius=1.0)
    markers = space.sample_markers(density=2000.0, max_count=100000, rng=np.random.default_rng(1))
    expected = 2000.0 * 4 / 3 * np.pi
    assert abs(len(markers) - expected) < 0.06 * expected
    assert space.contains(markers).all()


# ---------------------------------------------------------------- allocation
def test_borchert_honda_splits_by_lambda_at_a_branch_point():
    # One node (the root) carrying an apical bud and a lateral bud, both lit: Q_base = 2, pool = alpha * 2.
    v, subtree = allocate(np.array([-1]), np.array([True]), np.array([0]), np.array([0, 0]),
                          np.array([True, False]), np.array([1.0, 1.0]), model="borchert_honda",
                          alpha=2.0, lam=0.75, kappa=0.5)
    assert subtree[0] == pytest.approx(2.0)
    assert v == pytest.approx([3.0, 1.0])  # 4 * 0.75 and 4 * 0.25


def test_priority_model_gives_the_apical_bud_the_largest_share():
    # An axis of three nodes, apical bud on the tip, three lit lateral buds: apical ranks first.
    parent = np.array([-1, 0, 1])
    v, _ = allocate(parent, np.array([True, False, False]), np.zeros(3, int), np.array([2, 0, 1, 2]),
                    np.array([True, False, False, False]), np.ones(4), model="priority", alpha=2.0,
                    lam=0.5, kappa=0.5)
    assert v.sum() == pytest.approx(8.0)
    assert v[0] == v.max() and v[0] > 2 * v[1:].max()


def test_subtree_sums_and_path_products_match_a_plain_walk():
    rng = np.random.default_rng(2)
    parent = np.concatenate([[-1], [rng.integers(0, i) for i in range(1, 300)]])
    values = rng.random(300)
    tables = jump_tables(parent)
    sums, products = subtree_sums(tables, values), path_products(tables, values)
    expected_sums, expected_products = values.copy(), values.copy()
    for i in range(299, 0, -1):
        expected_sums[parent[i]] += expected_sums[i]
    for i in range(1, 300):
        expected_products[i] *= expected_products[parent[i]]
    assert np.allclose(sums, expected_sums) and np.allclose(products, expected_products)


def _leader_length(skeleton: Skeleton) -> float:
    return float(skeleton.segment_lengths[skeleton.order == 0].sum())


def test_lambda_above_half_grows_a_longer_leader_than_below_half():
    space = profile_crown("ellipsoid", 1.0, 2.4, 0.3)
    lengths = {}
    for lam in (0.3, 0.7):
        params = {**SMALL, "lambda": lam, "tropism": 0.0, "crown_base": 3.0}
        lengths[lam] = _leader_length(grow_in_space(params, np.random.default_rng(4), space=space))
    assert lengths[0.7] > 1.2 * lengths[0.3]


def test_priority_smaller_kappa_puts_more_of_the_tree_into_the_leader():
    space = profile_crown("ellipsoid", 1.0, 2.4, 0.3)
    share = {}
    for kappa in (0.2, 0.9):
        params = {**SMALL, "allocation": "priority", "kappa": kappa, "tropism": 0.3, "iterations": 8}
        skeleton = grow_in_space(params, np.random.default_rng(4), space=space)
        share[kappa] = _leader_length(skeleton) / skeleton.total_length
    assert share[0.2] > 2 * share[0.9]


# ---------------------------------------------------------------- guides and steering
def test_guide_skeleton_is_kept_as_given():
    positions = np.array([[0, 0, 0], [0, 0, 0.4], [0, 0, 0.8], [0.3, 0, 1.0], [-0.3, 0.1, 1.1], [0, 0, 1.2]])
    guide = Skeleton(positions, [-1, 0, 1, 2, 2, 2], np.full(6, 0.02), [0, 0, 0, 1, 1, 0])
    grown = grow_in_space(SMALL, np.random.default_rng(0), space=_sphere_space(), guide=guide)
    assert len(grown) > 3 * len(guide)
    assert np.array_equal(grown.positions[:6], guide.positions)
    assert np.array_equal(grown.parent[:6], guide.parent)
    assert np.array_equal(grown.order[:6], guide.order)


def _alignment(skeleton: Skeleton, direction) -> float:
    """Length-weighted mean cosine between the internodes and a direction."""
    segments = skeleton.positions[1:] - skeleton.positions[skeleton.parent[1:]]
    return float((segments @ np.asarray(direction)).sum() / np.linalg.norm(segments, axis=1).sum())


def test_direction_field_bends_growth_toward_it():
    space = _sphere_space()
    alignment = {}
    for weight in (0.0, 0.5):
        steering = MarkerSteering(attraction=lambda pts: np.tile([1.0, 0.0, 0.0], (len(pts), 1)))
        skeleton = grow_in_space({**SMALL, "attraction_weight": weight, "crown_base": 1.0},
                                 np.random.default_rng(6), space=space, steering=steering)
        alignment[weight] = _alignment(skeleton, [1.0, 0.0, 0.0])
    assert alignment[0.5] > alignment[0.0] + 0.15


def test_brush_stroke_pulls_shoots_along_the_stroke():
    space = _sphere_space()
    stroke = np.array([[-0.7, 0.0, 0.9], [0.7, 0.0, 0.9]])
    along = {}
    for strokes in ((), (stroke,)):
        skeleton = grow_in_space({**SMALL, "crown_base": 1.0}, np.random.default_rng(6), space=space,
                                 steering=MarkerSteering(strokes=strokes, sigma=0.1))
        segments = skeleton.positions[1:] - skeleton.positions[skeleton.parent[1:]]
        along[len(strokes)] = float(np.abs(segments[:, 0]).sum() / np.linalg.norm(segments, axis=1).sum())
    assert along[1] > along[0] + 0.03


# ---------------------------------------------------------------- the rest of the model
def test_shadow_falls_below_a_node_not_above():
    grid = ShadowGrid(_sphere_space(), 0.1)
    grid.cast(np.array([[0.0, 0.0, 0.9]]))
    light = grid.light(np.array([[0.0, 0.0, 1.05], [0.0, 0.0, 0.75], [0.1, 0.1, 0.65]]))
    assert light[0] == pytest.approx(1.0 + grid.a / grid.exposure)  # above: unshaded, own shadow cancelled
    assert light[1] < light[0] and light[2] < light[0]


def test_shadow_propagation_grows_a_tree():
    skeleton = grow({**SMALL, "resource": "shadow"}, np.random.default_rng(0))
    assert len(skeleton) > 100


def test_radii_never_grow_toward_the_tips():
    skeleton = grow(SMALL, np.random.default_rng(0))
    assert np.all(skeleton.radius[1:] <= skeleton.radius[skeleton.parent[1:]] + 1e-7)


def test_every_branch_tip_off_the_trunk_carries_leaves():
    skeleton = grow(SMALL, np.random.default_rng(0))
    tips = skeleton.tips[skeleton.order[skeleton.tips] >= 1]
    assert np.isin(tips, skeleton.leaf_node).all()


def test_shedding_drops_branches_but_keeps_a_valid_tree():
    full = grow({**SMALL, "iterations": 25}, np.random.default_rng(0))
    shed = grow({**SMALL, "iterations": 25, "shed_ratio": 0.5, "shed_patience": 1}, np.random.default_rng(0))
    assert 20 < len(shed) < len(full)


def test_schedule_phases_override_then_return_to_base():
    params = validate({**SMALL, "tropism": -0.3, "schedule": [[0, {"tropism": 0.8}], [5, {}]]})
    assert at_iteration(params, 0)["tropism"] == 0.8 and at_iteration(params, 4)["tropism"] == 0.8
    assert at_iteration(params, 5)["tropism"] == -0.3


def test_tree_is_scaled_to_its_height():
    skeleton = grow({**SMALL, "height": 7.5}, np.random.default_rng(0))
    assert skeleton.height == pytest.approx(7.5, rel=1e-5)
    assert abs(skeleton.positions[0]).max() == 0.0


def test_same_params_and_seed_give_identical_arrays():
    params = {**SMALL, "allocation": "priority", "apical_abort": 0.3, "crown_shape": "lobes"}
    first, second = grow(params, np.random.default_rng(9)), grow(params, np.random.default_rng(9))
    for name, array in first.to_arrays().items():
        assert array.tobytes() == second.to_arrays()[name].tobytes(), name
    other = grow(params, np.random.default_rng(10))
    assert other.positions.shape != first.positions.shape or not np.array_equal(other.positions, first.positions)


@pytest.mark.parametrize("name", [p.name for p in species.list_presets("colonization")])
def test_every_preset_grows_a_valid_skeleton_with_two_seeds(name):
    for seed in (0, 1):
        params = species.sample(name, np.random.default_rng(seed))
        skeleton = species.grow(params, species.rng_for(params))
        assert isinstance(skeleton, Skeleton)
        assert len(skeleton) > 40 and skeleton.n_leaves > 0
        assert skeleton.height == pytest.approx(params["height"], rel=1e-4)


def test_there_are_at_least_twenty_presets():
    assert len(species.list_presets("colonization")) >= 20


@pytest.mark.parametrize("bad, key", [
    ({"crown_radus": 3.0}, "crown_radus"),
    ({"lambda": 1.5}, "lambda"),
    ({"iterations": "many"}, "iterations"),
    ({"iterations": 2.5}, "iterations"),
    ({"allocation": "greedy"}, "allocation"),
    ({"occupancy_radius": 6.0, "perception_radius": 5.0}, "perception_radius"),
    ({"schedule": [[0, {"crown_radius": 3.0}]]}, "crown_radius"),
    ({"schedule": [[3, {}], [1, {}]]}, "schedule"),
    ({"seed": -1}, "seed"),
])
def test_bad_parameters_are_rejected_naming_the_key(bad, key):
    with pytest.raises(ParameterError, match=key):
        grow({**SMALL, **bad}, np.random.default_rng(0))
