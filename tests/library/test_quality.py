"""Quality of the LOD chain as the library measures it: alpha-tested coverage (cards shrunk to their texture's
opaque share, unculled depth-only GL passes, software raster for the impostor), the sliced impostor, exact GLB
size without instancing, validate's IoU report, the fitted bark/leaf split, and the IoU target per preset."""
from __future__ import annotations

import json

import numpy as np
import pytest

from farm.library.asset import build_asset, leaf_alphas
from farm.library.catalog import IOU_TARGET
from farm.library.gltf_asset import asset_to_glb, glb_size
from farm.library.quality import FLOOR_MARGIN, catalog_quality
from farm.library.spec import parse_library_spec
from farm.tree_chain import tree_seed
from species.timing import StageTimer
from renderers.alpha_coverage import CoverageError, opaque_fraction, shrunk_cards, triangle_coverage
from renderers.camera import orthographic_camera, perspective_camera
from renderers.framing import framing_points
from renderers.silhouette_metric import switch_camera
from species.meshing.gltf import read_glb_json
from species.meshing.tubes_and_cards import leaf_part
from species.studio.pbr_textures import leaf_atlas
from species.skeleton import Skeleton
from species.tree_mesh import MeshPart, TreeMesh



@pytest.fixture(scope="module")
def renderer():
    from renderers.gl_coverage import CoverageRenderer

    r = CoverageRenderer(64)
    yield r
    r.close()


def _cards(rng: np.random.Generator, count: int) -> MeshPart:
    """`count` randomly placed and turned leaf cards (0.1 m wide, 0.2 m long) as `leaf_part` makes them."""
    transforms = np.tile(np.eye(4), (count, 1, 1))
    for i in range(count):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        transforms[i, :3, :3] = q * np.array([0.1, 0.1, 0.2])
        transforms[i, :3, 3] = rng.uniform(-1.0, 1.0, 3) + [0.0, 0.0, 2.0]
    skeleton = Skeleton(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]), np.array([-1, 0]), np.array([0.1, 0.05]),
                        np.array([0, 0]), leaves=transforms, leaf_node=np.ones(count, np.int32))
    return leaf_part(skeleton)


def _card_areas(cards: MeshPart) -> np.ndarray:
    corners = np.asarray(cards.vertices, np.float64).reshape(-1, 4, 3)
    return np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0]), axis=1)


@pytest.mark.parametrize("tile", [0, 1])
def test_shrunk_cards_cover_the_opaque_share_of_each_leaf_tile_about_the_same_centre(tile):
    alpha = leaf_alphas(leaf_atlas((0.2, 0.4, 0.1), 64))[tile]
    fraction = opaque_fraction(alpha)
    cards = _cards(np.random.default_rng(tile), 5)
    shrunk = shrunk_cards(cards, fraction)
    assert 0.0 < fraction < 1.0
    assert _card_areas(shrunk) == pytest.approx(fraction * _card_areas(cards), rel=1e-5)
    np.testing.assert_allclose(shrunk.vertices.reshape(-1, 4, 3).mean(axis=1),
                               cards.vertices.reshape(-1, 4, 3).mean(axis=1), atol=1e-5)
    assert np.array_equal(shrunk.faces, cards.faces) and shrunk.n_faces == 2 * 5


def test_opaque_fraction_rejects_a_tile_without_opaque_texels():
    with pytest.raises(CoverageError, match="opaque"):
        opaque_fraction(np.zeros((8, 8), bool))


def test_coverage_renderer_without_culling_covers_the_pixels_of_double_sided_cards(renderer):
    from renderers.gl_depth import DepthRenderer

    cards = _cards(np.random.default_rng(7), 40)
    tree = TreeMesh(bark=MeshPart.empty(), leaves=cards, name="cards")
    points = np.asarray(cards.vertices, np.float64)
    culled = DepthRenderer(64)
    try:
        culled.load(tree)
        for azimuth in (0.0, 100.0, 250.0):
            camera = switch_camera(points, azimuth, 128)
            expected = culled.part_depths(camera, split_orders=False).leaves > 0
            assert expected.any()
            assert np.array_equal(renderer.coverage(tree, camera), expected)
    finally:
        culled.close()


def test_triangle_coverage_cuts_a_card_to_its_alpha():
    vertices = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 0.0, 2.0], [-1.0, 0.0, 2.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uvs = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    left_half = np.zeros((8, 8), bool)
    left_half[:, :4] = True
    camera = orthographic_camera(vertices, 0.0, 0.0, 64)
    opaque = triangle_coverage(camera, vertices, faces)
    cut = triangle_coverage(camera, vertices, faces, uvs, left_half)
    assert cut.sum() == pytest.approx(opaque.sum() / 2, rel=0.1)
    assert not (cut & ~opaque).any()


def test_triangle_coverage_interpolates_uvs_perspective_correctly_on_a_slanted_plane():
    # A 2 m square seen at 70 deg from a camera 3 m away: the left half (u < 0.5, by texture) must cover the
    # pixels whose rays meet the plane at x < 0, which affine interpolation misses by several pixels.
    vertices = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [1.0, 0.0, 1.0], [-1.0, 0.0, 1.0]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uvs = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    left_half = np.zeros((64, 64), bool)
    left_half[:, :32] = True
    camera = perspective_camera(vertices, 70.0, 0.0, 96, fov_deg=70.0, distance_scale=0.6)
    cut = triangle_coverage(camera, vertices, faces, uvs, left_half)
    rows, cols = np.nonzero(triangle_coverage(camera, vertices, faces))
    near = camera.unproject(np.stack([cols, rows], axis=1).astype(float), np.full(len(rows), 1.0))
    far = camera.unproject(np.stack([cols, rows], axis=1).astype(float), np.full(len(rows), 2.0))
    hit_x = near[:, 0] - near[:, 1] * (far[:, 0] - near[:, 0]) / (far[:, 1] - near[:, 1])  # ray meets y = 0
    expected = hit_x < 0.0
    clear = np.abs(hit_x) > 2 * 2.0 / 64  # two texels off the cut line
    assert expected[clear].any() and (~expected[clear]).any()
    assert np.array_equal(cut[rows, cols][clear], expected[clear])


def test_impostor_planes_cross_on_the_trunk(sapling):
    bark = sapling.lod0.bark
    trunk = bark.vertices[bark.attributes["order"] == 0, :2].astype(np.float64)
    np.testing.assert_allclose(sapling.impostor.centre[:2], trunk.mean(axis=0), atol=1e-9)


@pytest.fixture(scope="module")
def sapling(renderer):
    spec = parse_library_spec({"species": {"sc_young_sapling": 1}, "texture_size": 64, "impostor_tile": 32})
    return build_asset("sc_young_sapling", tree_seed(3, 0), spec, renderer, StageTimer())


def test_without_twig_cards_every_level_is_the_fits_plain_candidate_within_its_budget(sapling, renderer):
    import farm.library.asset as asset_module

    assert sapling.twig_atlas is not None  # this tree draws twig cards by default: the option changes something
    fitted = []
    real_fit = asset_module.fit_lods
    asset_module.fit_lods = lambda *args, **kwargs: fitted.append(real_fit(*args, **kwargs)) or fitted[-1]
    try:
        for twig_cards in (True, False):
            spec = parse_library_spec({"species": {"sc_young_sapling": 1}, "texture_size": 64, "impostor_tile": 32,
                                       "twig_cards": twig_cards})
            plain = build_asset("sc_young_sapling", tree_seed(3, 0), spec, renderer, StageTimer())
    finally:
        asset_module.fit_lods = real_fit
    assert plain.twig_atlas is None and all(level.twigs is None for level in plain.levels)
    assert all(level.twigs is None for level in fitted[1])
    for level, with_cards, without, budget in zip(plain.levels[1:], fitted[0], fitted[1], spec.lod_budgets):
        # The same plain climb as with twig cards on: the option drops the twig candidates, nothing else.
        assert np.array_equal(with_cards.plain.mesh.bark.faces, without.plain.mesh.bark.faces)
        assert np.array_equal(with_cards.plain.skeleton.leaves, without.plain.skeleton.leaves)
        assert level.mesh is without.plain.mesh and level.n_triangles <= budget * plain.lod0.n_faces
        assert len(level.iou) == 8
    assert np.array_equal(plain.lod0.bark.vertices, sapling.lod0.bark.vertices)
    names = {material["name"] for material in read_glb_json(asset_to_glb(plain))["materials"]}
    assert not any(name.startswith("twigs_") for name in names) and "bark" in names


def test_cameras_framed_on_hull_points_equal_those_framed_on_every_vertex(sapling):
    lod0 = sapling.lod0
    every = np.concatenate([lod0.bark.vertices, lod0.leaves.vertices])
    hull = framing_points(lod0)
    assert len(hull) < len(every)
    for azimuth, px in ((11.25, 512), (200.0, 64)):
        a, b = switch_camera(every, azimuth, px), switch_camera(hull, azimuth, px)
        assert np.array_equal(a.K, b.K) and np.array_equal(a.world_to_camera, b.world_to_camera)
        assert (a.near, a.far) == (b.near, b.far)


def test_glb_size_without_instancing_is_the_length_of_that_file(sapling):
    assert glb_size(sapling, instanced=False) == len(asset_to_glb(sapling, instanced=False))
    assert glb_size(sapling) == len(asset_to_glb(sapling))


def test_impostor_has_at_most_16_triangles_and_a_tile_per_plane(sapling):
    atlas = sapling.impostor
    assert sapling.levels[-1].n_triangles <= 16
    tiles = (atlas.albedo.shape[0] // atlas.tile) * (atlas.albedo.shape[1] // atlas.tile)
    assert tiles >= len(atlas.azimuths) == sapling.levels[-1].n_triangles // 2
    for plane in range(len(atlas.azimuths)):
        row, col = atlas.tile_origin(plane)
        assert (atlas.albedo[row:row + atlas.tile, col:col + atlas.tile, 3] > 0).any()


def test_every_level_carries_eight_iou_figures_in_range(sapling):
    for level in sapling.levels[1:]:
        assert len(level.iou) == 8 and all(0.0 <= v <= 1.0 for v in level.iou)


def test_validate_judges_each_level_by_its_stored_half_pixel_floor(tmp_path):
    rows = [{"id": "a", "level_names": ["LOD0", "LOD1", "LOD2", "IMPOSTOR"], "switch_px": [0, 512, 128, 64],
             "iou_min": [1.0, 0.85, 0.5, 0.7], "iou_floor": [None, 0.86, 0.9, None]},
            {"id": "b", "level_names": ["LOD0", "LOD1"], "switch_px": [0, 512], "iou_min": [1.0, 0.8]}]
    (tmp_path / "catalog.json").write_text(json.dumps(rows))
    quality = catalog_quality(str(tmp_path))
    assert (quality.assets, quality.levels) == (2, 4)
    assert [(f.asset, f.level, f.meets) for f in quality.measured] == [("a", "LOD1", True), ("a", "LOD2", False)]
    assert quality.summary() == f"1 of 2 levels within {FLOOR_MARGIN} of their half-pixel floor (2 not measured)"
    for row in rows:
        row["iou_floor"] = None
    (tmp_path / "catalog.json").write_text(json.dumps(rows))
    assert "not measured" in catalog_quality(str(tmp_path)).summary()  # never judged against the old 0.9


@pytest.mark.parametrize("name", ["sc_broad_oak", "sc_weeping_willow"])
def test_dense_crowns_reach_the_target_at_every_switch(name, renderer):
    spec = parse_library_spec({"species": {name: 1}, "texture_size": 64, "impostor_tile": 64})
    asset = build_asset(name, tree_seed(0, 0), spec, renderer, StageTimer())
    worst = {level.name: min(level.iou) for level in asset.levels[1:]}
    assert min(worst.values()) >= IOU_TARGET, worst


# The half-pixel floor target, per preset, as benchmarks/bench_silhouette_floor.py measures it (tree_seed(0, 0),
# default spec). The presets whose worst level misses its half-pixel floor by more than 0.04 are listed and not run
# here (slow to build, and the bench measures them; a preset that comes to meet the target moves out of
# this list into the strict test); those within 0.02 of the line either way may fall on either side on another
# CPU's rasteriser. Every other preset must meet the target.
FLOOR_MISSES = {"bonsai", "maple", "sc_birch_oval", "sc_dense_beech", "sc_dome_shrub", "sc_multistem_shrub",
                "sc_open_fruit_tree", "sc_self_pruning_forest_tree", "sc_shadow_oak", "sc_spruce",
                "sc_superquadric_lobes", "sc_sympodial_candelabra", "sc_sympodial_lilac", "sc_young_sapling",
                "lsystem_abop_tree", "lsystem_bush", "lsystem_fractal_plant", "lsystem_monopodial", "lsystem_sympodial"}
# Least margin to the half-pixel floor within .02 of the line either way (-0.04 to 0.0): may flip on another
# rasteriser, so neither a pass nor a miss is held to.
FLOOR_BORDERLINE = {"black_oak", "lombardy_poplar", "palm", "pine", "sc_broad_oak", "sc_columnar_poplar",
                    "sc_cypress_column", "sc_fir", "sc_flat_acacia", "sc_lobed_cloud", "sc_round_maple",
                    "sc_shadow_conifer", "sc_umbrella_pine", "sc_vase_elm", "sc_weeping_willow"}


def _floor_case(name: str):
    if name in FLOOR_MISSES:
        return pytest.param(name, marks=pytest.mark.xfail(run=False, reason="issue 26: below the half-pixel floor "
                                                                             "(benchmarks/bench_silhouette_floor.py)"))
    if name in FLOOR_BORDERLINE:
        return pytest.param(name, marks=pytest.mark.xfail(strict=False, reason="issue 26: within 0.02 of the line"))
    return name


def _preset_names() -> list[str]:
    import species

    return [preset.name for preset in species.list_presets()]


@pytest.mark.slow
@pytest.mark.parametrize("name", [_floor_case(name) for name in _preset_names()])
def test_every_level_is_within_its_half_pixel_floor(name, renderer):
    from farm.library.quality import FLOOR_MARGIN, asset_floors

    asset = build_asset(name, tree_seed(0, 0), parse_library_spec({"species": {name: 1}}), renderer, StageTimer())
    floors = asset_floors(asset, renderer)
    assert [f.level for f in floors] == ["LOD1", "LOD2", "LOD3", "IMPOSTOR"]
    missed = {f.level: f"IoU {f.iou:.3f} vs floor {f.floor:.3f}" for f in floors if not f.meets}
    assert not missed, f"{name}: more than {FLOOR_MARGIN} below the half-pixel floor: {missed}"


def test_lod2_climbs_to_a_bark_share_and_card_gain_no_neighbour_of_which_matches_lod0_better(renderer):
    import species
    from farm.library.asset import leaf_fractions
    from farm.library.lod_fit import BARK_SHARE_SCALES, CALIBRATION_AZIMUTHS, CARD_AREA_GAINS, fit_lods
    from renderers.alpha_coverage import coverage_tree
    from renderers.silhouette_metric import QUALITY_AZIMUTHS, closed_silhouette, silhouette_iou
    from species.studio.leaf_clusters import CLUSTER_AREA_GAIN
    from species.studio.lod import TreeLods

    assert not set(CALIBRATION_AZIMUTHS) & set(QUALITY_AZIMUTHS)
    params = species.sample("sassafras", np.random.default_rng(2))
    skeleton = species.grow(params, species.rng_for(params))
    lod0 = species.build_mesh(skeleton, params)
    lod0_fraction, card_fraction = leaf_fractions(leaf_atlas((0.2, 0.5, 0.1), 64))
    cover = coverage_tree(lod0, lod0_fraction)
    chosen = fit_lods(skeleton, lod0, cover, (0.4, 0.12), (512, 256), renderer, lod0_fraction, card_fraction)[1].plain
    share0 = lod0.bark.n_faces / lod0.n_faces
    points = framing_points(lod0)

    def score(lod):
        lod_cover = coverage_tree(lod.mesh, lod0_fraction, card_fraction)
        return min(silhouette_iou(closed_silhouette(renderer.coverage(cover, switch_camera(points, az, 256))),
                                  closed_silhouette(renderer.coverage(lod_cover, switch_camera(points, az, 256))))
                   for az in CALIBRATION_AZIMUTHS)

    def neighbours(index, count):
        return [i for i in (index - 1, index + 1) if 0 <= i < count]

    lods = TreeLods(skeleton, lod0)
    by_share = [lods.build(2, 0.12, 256, bark_share=min(scale * share0, 1.0)) for scale in BARK_SHARE_SCALES]
    share_scores = [score(lod) for lod in by_share]
    share = [lod.mesh.bark.n_faces for lod in by_share].index(chosen.mesh.bark.n_faces)
    assert all(share_scores[share] >= share_scores[i] for i in neighbours(share, len(BARK_SHARE_SCALES)))
    chosen_share = min(BARK_SHARE_SCALES[share] * share0, 1.0)
    by_gain = [lods.build(2, 0.12, 256, bark_share=chosen_share, card_area_gain=gain) for gain in CARD_AREA_GAINS]
    gain = [np.array_equal(lod.skeleton.leaves, chosen.skeleton.leaves) for lod in by_gain].index(True)
    gain_scores = [score(lod) for lod in by_gain]
    assert gain_scores[gain] >= gain_scores[CARD_AREA_GAINS.index(CLUSTER_AREA_GAIN)]
    assert all(gain_scores[gain] >= gain_scores[i] for i in neighbours(gain, len(CARD_AREA_GAINS)))
    assert chosen.n_triangles <= 0.12 * lod0.n_faces


class _ScriptedViews:
    """Stands in for CalibrationViews: the IoU of each view is given, and every draw is counted."""

    def __init__(self, ious):
        self.ious, self.drawn = list(ious), []

    def iou(self, view, cover):
        self.drawn.append((view, cover))
        return self.ious[view]


def test_a_judgement_draws_a_further_view_only_while_the_candidate_can_still_beat_its_rival():
    from farm.library.lod_fit import Judgement

    made = []
    views = _ScriptedViews([0.80, 0.60])
    judgement = Judgement(views, lambda: made.append("cover") or "cover")
    assert judgement.least(2, beat=0.85) == 0.80  # the first view already falls to the rival: no second draw
    assert views.drawn == [(0, "cover")]
    assert judgement.least(2, beat=0.70) == 0.60  # it may still beat 0.70: the second view is drawn
    assert judgement.least(2) == 0.60 and judgement.least(1) == 0.80
    assert views.drawn == [(0, "cover"), (1, "cover")] and made == ["cover"]  # the cover is made once

    for ious in ([0.9, 0.5], [0.5, 0.9], [0.7, 0.7]):
        for beat in (0.4, 0.5, 0.6, 0.7, 0.8, 0.95):
            lazy = Judgement(_ScriptedViews(ious), "cover").least(2, beat)
            assert (lazy > beat) == (min(ious) > beat)  # the comparison comes out as the full least's would
            assert lazy >= min(ious)


def test_the_climb_reaches_the_same_index_with_early_stopping_scores():
    from farm.library.lod_fit import Judgement, climb_ladder

    rng = np.random.default_rng(5)
    for _ in range(50):
        ious = rng.uniform(0.3, 1.0, size=(7, 2))
        full = lambda index, beat=-np.inf: float(ious[index].min())  # noqa: E731
        judgements = [Judgement(_ScriptedViews(row), "cover") for row in ious]
        lazy = lambda index, beat=-np.inf: judgements[index].least(2, beat)  # noqa: E731
        start = int(rng.integers(7))
        assert climb_ladder(lazy, start, 7) == climb_ladder(full, start, 7)
        assert sum(len(j.views.drawn) for j in judgements) <= 2 * sum(bool(j.views.drawn) for j in judgements)


def test_the_impostor_keeps_the_axis_share_and_alpha_growth_that_match_lod0_best_from_the_calibration_views(
        renderer):
    from farm.library.asset import leaf_fractions
    from farm.library.lod_fit import (IMPOSTOR_AXIS_SHARES, IMPOSTOR_CALIBRATION_AZIMUTHS, IMPOSTOR_GROWTHS,
                                      fit_impostor)
    from renderers.alpha_coverage import coverage_tree
    from renderers.impostor import AXIS_SHARE, render_impostor
    from renderers.silhouette_metric import closed_silhouette, silhouette_iou

    assert IMPOSTOR_AXIS_SHARES[0] == AXIS_SHARE and len(set(IMPOSTOR_AXIS_SHARES)) > 1
    # A sparse plant whose twigs fall between the texels a pixel samples at 64 px: growing its alpha wins there.
    asset = build_asset("lsystem_dichotomous", tree_seed(0, 0), parse_library_spec({"species": {"lsystem_dichotomous": 1}}),
                        renderer, StageTimer())
    cover = coverage_tree(asset.lod0, leaf_fractions(asset.leaf_atlases["summer"])[0])
    rendered = {share: render_impostor(renderer, cover, tile=asset.impostor.tile, axis_share=share)
                for share in IMPOSTOR_AXIS_SHARES}
    points = framing_points(asset.lod0)
    cameras = [switch_camera(points, a, 64) for a in IMPOSTOR_CALIBRATION_AZIMUTHS]
    references = [closed_silhouette(renderer.coverage(cover, c)) for c in cameras]

    def calibration_score(atlas) -> float:
        ious = [silhouette_iou(r, closed_silhouette(atlas.coverage(c))) for r, c in zip(references, cameras)]
        return min(ious) + float(np.mean(ious))

    scores = {(share, t): calibration_score(rendered[share].grown(t)) for share in IMPOSTOR_AXIS_SHARES
              for t in IMPOSTOR_GROWTHS}
    asked = []
    chosen = fit_impostor(lambda shares: asked.append(tuple(shares)) or [rendered[share] for share in shares],
                          points, cover, renderer, 64)
    assert asked == [tuple(IMPOSTOR_AXIS_SHARES)]  # every slicing rendered in one call
    assert calibration_score(chosen) == max(scores.values())
    assert max(scores, key=scores.get)[1] == 1  # grown by a texel here
    assert asset.impostor.albedo.tobytes() == chosen.albedo.tobytes()  # what the build keeps
