"""The twig atlas rendered from LOD0 and measured as runs of opaque texels (renderers.twig_atlas)."""
import numpy as np
import pytest

import species
from renderers.alpha_coverage import triangle_coverage
from renderers.framing import framing_points
from renderers.gl_coverage import CoverageRenderer
from renderers.silhouette_metric import switch_camera
from renderers.twig_atlas import render_twig_atlas
from species.studio.lod import TreeLods
from species.studio.twig_cards import TwigAtlas


@pytest.fixture(scope="module")
def rendered():
    skeleton, lod0 = species.rebuild(species.sample("sc_young_sapling", np.random.default_rng(3)))
    lod = TreeLods(skeleton, lod0).build(2, 0.12, 256, twigs=True)
    assert lod.twigs is not None and len(lod.twigs) > 0
    renderer = CoverageRenderer(64)
    try:
        image = render_twig_atlas(renderer, TwigAtlas.pack([lod.twigs], [0.01], 512 * 512), lod0)
    finally:
        renderer.close()
    return lod0, image


def test_atlas_marks_bark_and_leaf_texels_inside_tiles_only(rendered):
    _, image = rendered
    index = image.layout.card_index
    assert set(np.unique(image.mask)) <= {0, 1, 2} and (image.mask == 1).any()
    assert not image.opaque[index < 0].any()
    assert image.normal.shape[:2] == tuple(-(-n // 2) for n in image.mask.shape)


def test_bare_albedo_cuts_the_leaves_and_keeps_the_twigs(rendered):
    _, image = rendered
    summer = image.albedo((0.2, 0.1, 0.05), (0.1, 0.5, 0.1))
    bare = image.albedo((0.2, 0.1, 0.05), None)
    assert np.array_equal(summer[..., 3] > 0, image.opaque)
    assert np.array_equal(bare[..., 3] > 0, image.mask == 1)


def test_opaque_runs_cover_exactly_what_the_alpha_tested_cards_do(rendered):
    lod0, image = rendered
    cards = image.layout.card_part(0)
    runs = image.opaque_runs(0)
    camera = switch_camera(framing_points(lod0), 33.0, 256)
    tested = triangle_coverage(camera, cards.vertices, cards.faces, cards.uvs, image.opaque)
    drawn = triangle_coverage(camera, runs.vertices, runs.faces)
    assert tested.sum() > 100
    # Identical but for pixel centres on a texel's edge, where the two tests may round apart.
    assert (tested ^ drawn).sum() <= 0.01 * tested.sum()


def test_a_level_repeating_the_nearer_level_s_cards_draws_their_tiles_and_only_its_own_beside(rendered):
    lod0, image = rendered
    cards = image.layout.levels[0]
    renderer = CoverageRenderer(64)
    try:
        both = render_twig_atlas(renderer, TwigAtlas.pack([cards, cards], [0.01, 0.02], 512 * 512), lod0)
    finally:
        renderer.close()
    assert both.mask.shape == image.mask.shape and np.array_equal(both.mask, image.mask)  # no second copy drawn
    near, far = both.opaque_runs(0), both.opaque_runs(1)
    assert np.array_equal(near.vertices, far.vertices) and np.array_equal(near.faces, far.faces)
    assert np.array_equal(both.layout.card_part(1).uvs, both.layout.card_part(0).uvs)
