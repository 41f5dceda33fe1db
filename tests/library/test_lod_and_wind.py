"""LOD budgets on every Weber-Penn preset, wind attributes, collision capsules (no rendering)."""
from __future__ import annotations

import numpy as np
import pytest

import species
from species.studio.collision import capsule_mesh, collision_capsules
from species.studio.lod import build_lod
from species.studio.wind import wind_attributes


def _tree(name: str, seed: int = 1):
    params = species.sample(name, np.random.default_rng(seed))
    skeleton = species.grow(params, species.rng_for(params))
    return skeleton, species.build_mesh(skeleton, params)


@pytest.mark.parametrize("name", [p.name for p in species.list_presets("weber_penn")])
def test_lod_budgets_hold_on_every_weber_penn_preset(name):
    skeleton, lod0 = _tree(name)
    for level, budget in ((1, 0.40), (2, 0.12), (3, 0.04)):
        lod = build_lod(skeleton, lod0, level, budget)
        assert 0 < lod.n_triangles <= budget * lod0.n_faces
        if skeleton.n_leaves:
            assert lod.skeleton.n_leaves >= 1


@pytest.mark.parametrize("name", [p.name for p in species.list_presets("weber_penn")])
def test_every_weber_penn_preset_goes_through_the_lod_chain_with_several_seeds(name):
    for seed in (0, 9, 23):
        skeleton, lod0 = _tree(name, seed)
        for level, budget in ((1, 0.40), (2, 0.12), (3, 0.04)):
            assert build_lod(skeleton, lod0, level, budget).n_triangles <= budget * lod0.n_faces


@pytest.mark.parametrize("budget", [0.01, 0.002])
def test_a_tiny_lod3_budget_is_met_with_three_sided_trunk_and_few_cards(budget):
    skeleton, lod0 = _tree("maple", 0)
    lod = build_lod(skeleton, lod0, 3, budget)
    assert 0 < lod.n_triangles <= budget * lod0.n_faces
    assert lod.mesh.bark.n_faces > 0 and 1 <= lod.n_clusters
    assert set(np.unique(lod.skeleton.order)) <= {0, 1}


def test_wind_attributes_are_in_range_and_phase_is_constant_along_each_branch():
    skeleton, mesh = _tree("maple")
    branch = mesh.bark.attributes["branch"]
    wind, pivot = wind_attributes(skeleton, mesh.bark.vertices, branch)
    assert wind.shape == (mesh.bark.n_vertices, 4) and pivot.shape == (mesh.bark.n_vertices, 3)
    assert np.all((wind[:, 1] >= 0) & (wind[:, 1] <= 1)) and np.all((wind[:, 2] >= 0) & (wind[:, 2] < 1))
    assert np.all(wind[:, 0] == mesh.bark.attributes["order"])
    for column in (2, 0):
        lo = np.full(branch.max() + 1, np.inf)
        hi = np.full(branch.max() + 1, -np.inf)
        np.minimum.at(lo, branch, wind[:, column])
        np.maximum.at(hi, branch, wind[:, column])
        used = np.isfinite(lo)
        assert np.array_equal(lo[used], hi[used])
    # the trunk's pivot is the root at the origin
    assert np.allclose(pivot[branch == 0], 0.0)


def test_collision_capsules_cover_the_trunk_base_and_top():
    skeleton, _ = _tree("maple")
    capsules = collision_capsules(skeleton)
    assert capsules.shape[1] == 7 and np.all(capsules[:, 6] > 0)
    trunk = skeleton.branch_paths[0]
    assert np.allclose(capsules[0, :3], skeleton.positions[trunk[0]])


def test_capsule_mesh_is_each_capsule_closed_around_its_segment_as_trimesh_makes_it():
    import trimesh

    skeleton, _ = _tree("maple")
    capsules = collision_capsules(skeleton)
    mesh = capsule_mesh(capsules, sides=6)
    per = len(mesh.vertices) // len(capsules)
    for k, (p0, p1, radius) in enumerate(zip(capsules[:, :3], capsules[:, 3:6], capsules[:, 6])):
        vertices = mesh.vertices[k * per:(k + 1) * per].astype(np.float64)
        faces = mesh.faces[(mesh.faces >= k * per).all(axis=1) & (mesh.faces < (k + 1) * per).all(axis=1)] - k * per
        # Every vertex lies on the capsule's surface: its radius from the segment p0-p1.
        axis = (p1 - p0) / np.linalg.norm(p1 - p0)
        along = np.clip((vertices - p0) @ axis, 0.0, np.linalg.norm(p1 - p0))
        distance = np.linalg.norm(vertices - (p0 + along[:, None] * axis), axis=1)
        np.testing.assert_allclose(distance, radius, rtol=1e-5, atol=1e-6)
        closed = trimesh.Trimesh(vertices, faces, process=False)
        assert closed.is_watertight and closed.volume > 0  # closed, wound outward
        # The same capsule trimesh makes on its own, placed on the segment.
        made = trimesh.creation.capsule(height=float(np.linalg.norm(p1 - p0)), radius=float(radius), count=[6, 6])
        turn = trimesh.geometry.align_vectors([0.0, 0.0, 1.0], axis)
        turn[:3, 3] = 0.5 * (p0 + p1)
        made.apply_transform(turn)
        np.testing.assert_allclose(vertices, made.vertices, atol=1e-5)
        assert np.array_equal(faces, made.faces)
        outward = vertices - (p0 + along[:, None] * axis)  # from the segment to the vertex
        assert np.all(np.einsum("vi,vi->v", mesh.normals[k * per:(k + 1) * per], outward) > 0)


@pytest.mark.parametrize("name", ["palm", "weeping_willow"])
def test_thick_branches_stay_within_a_pixel_of_their_lod0_axis_at_the_switch_size(name):
    from species.studio.lod import THICK_TOLERANCE_PX, metres_per_pixel

    skeleton, lod0 = _tree(name, 0)
    for level, budget, px in ((1, 0.40, 512), (3, 0.04, 128)):
        lod = build_lod(skeleton, lod0, level, budget, px)
        tolerance = THICK_TOLERANCE_PX * metres_per_pixel(skeleton, px)
        trunk = skeleton.branch_paths[0]
        kept = np.flatnonzero(np.isin(trunk, lod.original_node))
        assert kept[0] == 0 and kept[-1] == len(trunk) - 1
        for lo, hi in zip(kept[:-1], kept[1:]):
            a, b = skeleton.positions[trunk[lo]].astype(float), skeleton.positions[trunk[hi]].astype(float)
            inner = skeleton.positions[trunk[lo + 1:hi]].astype(float)
            t = np.clip((inner - a) @ (b - a) / max((b - a) @ (b - a), 1e-12), 0, 1)
            assert np.all(np.linalg.norm(inner - (a + t[:, None] * (b - a)), axis=1) <= tolerance + 1e-6)


def test_within_a_roomy_budget_a_smaller_switch_size_keeps_less_bark():
    skeleton, lod0 = _tree("sassafras", 0)
    triangles = [build_lod(skeleton, lod0, 1, 1.0, px).mesh.bark.n_faces for px in (1024, 512, 128, 32)]
    assert triangles == sorted(triangles, reverse=True) and triangles[-1] < triangles[0]


@pytest.mark.parametrize("switch_px", [0, 5000, 12.5, True])
def test_a_switch_size_out_of_range_is_rejected_with_its_value(switch_px):
    from species.studio.lod import LodBudgetError

    skeleton, lod0 = _tree("maple", 0)
    with pytest.raises(LodBudgetError, match="switch size"):
        build_lod(skeleton, lod0, 1, 0.4, switch_px)


def test_branches_thinner_than_two_pixels_at_the_switch_are_bare_three_sided_tubes():
    from species.studio.lod import THICK_BRANCH_PX, metres_per_pixel

    skeleton, lod0 = _tree("sassafras", 0)
    lod = build_lod(skeleton, lod0, 2, 0.12, 256)
    simplified, bark = lod.skeleton, lod.mesh.bark
    branch = bark.attributes["branch"]
    # Widening only raises radii: a branch drawn at most 2 px wide started thinner than that before it.
    thin = 2 * simplified.radius[simplified.branch_starts] < THICK_BRANCH_PX * metres_per_pixel(skeleton, 256)
    meshed = np.unique(branch)
    thin_meshed = meshed[thin[meshed]]
    assert len(thin_meshed) > 10
    for b in thin_meshed[:40]:
        assert (branch == b).sum() % 4 == 0  # rings of 3 sides + seam, no apex


def test_the_bark_share_moves_triangles_between_bark_and_leaf_cards():
    skeleton, lod0 = _tree("maple", 0)
    lean, heavy = (build_lod(skeleton, lod0, 1, 0.40, 512, bark_share=share) for share in (0.1, 0.8))
    assert lean.mesh.bark.n_faces < heavy.mesh.bark.n_faces
    assert lean.mesh.leaves.n_faces > heavy.mesh.leaves.n_faces
    for lod in (lean, heavy):
        assert lod.n_triangles <= 0.40 * lod0.n_faces


@pytest.mark.parametrize("share", [-0.1, 1.5])
def test_a_bark_share_outside_zero_to_one_is_rejected_with_its_value(share):
    from species.studio.lod import LodBudgetError

    skeleton, lod0 = _tree("maple", 0)
    with pytest.raises(LodBudgetError, match=str(share)):
        build_lod(skeleton, lod0, 1, 0.4, 512, bark_share=share)


def test_branches_rank_by_the_largest_value_in_their_subtree():
    from species.studio.lod import subtree_maximum

    # 0 <- 1 <- 2 <- 3 and 0 <- 4: a stub (1) carrying a long limb (2) ranks with the limb
    parent = np.array([-1, 0, 1, 2, 0])
    ranked = subtree_maximum(np.array([9.0, 2.0, 5.0, 1.0, 7.0]), parent)
    np.testing.assert_array_equal(ranked, [9.0, 5.0, 5.0, 1.0, 7.0])
    rng = np.random.default_rng(4)
    parent = np.concatenate([[-1], rng.integers(0, np.arange(1, 300))])
    value = rng.uniform(size=300)
    ranked = subtree_maximum(value, parent)
    assert np.all(ranked >= value) and np.all(ranked[1:] <= ranked[parent[1:]])


def test_a_larger_card_area_gain_gives_larger_cluster_cards_within_the_same_budget():
    skeleton, lod0 = _tree("maple", 0)
    small, large = (build_lod(skeleton, lod0, 3, 0.04, 128, card_area_gain=gain) for gain in (1.0, 3.0))
    assert small.n_triangles == large.n_triangles <= 0.04 * lod0.n_faces

    def areas(lod):
        corners = lod.skeleton.leaf_corners().astype(np.float64)
        return np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0]), axis=1)

    assert areas(large).sum() > areas(small).sum()
    assert np.all(areas(large) >= areas(small) * (1 - 1e-6))


def test_a_card_area_gain_that_is_not_positive_is_rejected_with_its_value():
    from species.studio.lod import LodBudgetError

    skeleton, lod0 = _tree("maple", 0)
    with pytest.raises(LodBudgetError, match="card area gain 0"):
        build_lod(skeleton, lod0, 1, 0.4, 512, card_area_gain=0.0)


def test_a_card_that_is_one_leaf_is_that_leaf_and_only_merged_cards_are_clumps():
    from species.studio.leaf_clusters import LeafCards
    from species.studio.lod import CLUMP_ATTRIBUTE, card_clumps

    skeleton, lod0 = _tree("maple", 0)
    lod = build_lod(skeleton, lod0, 1, 0.4, 512)
    clumps = card_clumps(lod.mesh.leaves)
    assert len(clumps) == len(lod.skeleton.leaves) and clumps.any() and not clumps.all()
    assert np.array_equal(lod.mesh.leaves.attributes[CLUMP_ATTRIBUTE], np.repeat(clumps, 4))
    lod0_leaves = {m.astype(np.float32).tobytes() for m in skeleton.leaves}
    is_a_leaf = np.array([m.astype(np.float32).tobytes() in lod0_leaves for m in lod.skeleton.leaves])
    assert np.array_equal(is_a_leaf, ~clumps)
    assert not card_clumps(lod0.leaves).any()  # LOD0's cards are all single leaves
    cards = LeafCards(skeleton.leaves)
    _, _, merged = cards.cluster(skeleton.leaf_node, 1)
    assert merged.tolist() == [True]  # every leaf in one card


def test_a_coverage_tree_cuts_single_leaves_and_clumps_to_their_own_tiles_share():
    from renderers.alpha_coverage import coverage_tree
    from species.studio.lod import card_clumps

    skeleton, lod0 = _tree("maple", 0)
    lod = build_lod(skeleton, lod0, 2, 0.12, 256)
    clumps = card_clumps(lod.mesh.leaves)
    assert clumps.any() and not clumps.all()

    def areas(part):
        c = part.vertices.reshape(-1, 4, 3).astype(np.float64)
        return np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 3] - c[:, 0]), axis=1)

    full = areas(lod.mesh.leaves)
    cut = areas(coverage_tree(lod.mesh, 0.25, 0.64).leaves)
    np.testing.assert_allclose(cut[~clumps], 0.25 * full[~clumps], rtol=1e-4)
    np.testing.assert_allclose(cut[clumps], 0.64 * full[clumps], rtol=1e-4)
    np.testing.assert_allclose(areas(coverage_tree(lod.mesh, 0.25).leaves), 0.25 * full, rtol=1e-4)
