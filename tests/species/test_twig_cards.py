"""Twig cluster cards: which branches share a card, cards in the plane of their faces, the atlas layout and its
inverse (species.studio.twig_cards)."""
import dataclasses

import numpy as np
import pytest

import species
from species.studio.lod import TreeLods
from species.studio.twig_cards import (BUDGETED_MAX_PLANES, BUDGETED_TEXELS_PER_PIXEL, LEVEL_SPRAY_NORMAL_Z,
                                       TWIG_CARD_PLANES, TWIG_PADDING_TEXELS, UPRIGHT_PLANES, TwigAtlas, TwigCardError,
                                       twig_cards, twig_labels)


@pytest.fixture(scope="module")
def sapling():
    params = species.sample("sc_young_sapling", np.random.default_rng(3))
    return species.rebuild(params)


@pytest.fixture(scope="module")
def kept(sapling):
    skeleton, lod0 = sapling
    lod = TreeLods(skeleton, lod0).build(2, 0.12, 256)
    kept_branch = np.zeros(skeleton.n_branches, bool)
    kept_branch[skeleton.branch_id[lod.original_node]] = True
    assert 0 < kept_branch.sum() < skeleton.n_branches
    return kept_branch


def test_every_dropped_branch_gets_its_own_card_without_a_depth_limit(sapling, kept):
    labels = twig_labels(sapling[0], kept, None)
    assert (labels[kept] == -1).all()
    assert sorted(labels[~kept]) == list(range(int((~kept).sum())))


def test_depth_zero_gives_one_card_per_dropped_subtree(sapling, kept):
    skeleton = sapling[0]
    labels = twig_labels(skeleton, kept, 0)
    parent = skeleton.branch_parent
    roots = ~kept & kept[np.maximum(parent, 0)] & (parent >= 0)
    assert labels.max() + 1 == roots.sum()
    # A dropped branch shares its parent's card unless it is a subtree's root.
    inner = ~kept & ~roots
    assert (labels[inner] == labels[parent[inner]]).all()


def test_deeper_limits_never_give_fewer_cards(sapling, kept):
    counts = [twig_labels(sapling[0], kept, depth).max() + 1 for depth in (0, 1, 2, 3, None)]
    assert counts == sorted(counts)


def test_labels_of_the_wrong_shape_are_refused(sapling):
    with pytest.raises(TwigCardError, match="kept_branch of shape"):
        twig_labels(sapling[0], np.ones(3, bool), None)


@pytest.mark.parametrize("planes", [1, 2])
def test_cards_hold_their_faces_pressed_flat_inside_the_card(sapling, kept, planes):
    skeleton, lod0 = sapling
    cards = twig_cards(skeleton, lod0, twig_labels(skeleton, kept, None), planes)
    dropped_bark = np.flatnonzero(~kept[np.asarray(lod0.bark.attributes["branch"])[lod0.bark.faces[:, 0]]])
    # Every dropped face is drawn, on one card of its own cluster or (crossed, near a sector edge or the axis) on
    # each of them.
    assert np.array_equal(np.unique(cards.bark_faces), dropped_bark)
    copies = np.bincount(cards.bark_faces)[dropped_bark]
    assert copies.min() == 1 and copies.max() == planes
    assert len(np.unique(np.stack([cards.bark_faces, cards.bark_card]), axis=1).T) == len(cards.bark_faces)
    flat = cards.flattened(lod0)
    for part, card in ((flat.bark, cards.bark_card), (flat.leaves, cards.leaf_card)):
        card = np.repeat(card, 3)
        local = np.einsum("pj,pij->pi", part.vertices[part.faces].reshape(-1, 3) - cards.origin[card],
                          cards.axes[card])
        assert np.abs(local[:, 2]).max() < 1e-4  # on the card's plane
        assert (local[:, :2] >= -1e-4).all() and (local[:, :2] <= cards.extent[card] + 1e-4).all()
    assert np.allclose(np.einsum("cij,ckj->cik", cards.axes, cards.axes), np.eye(3), atol=1e-9)
    assert np.allclose(np.linalg.det(cards.axes), 1.0)


def test_crossed_cards_share_their_clusters_axis_and_take_the_faces_nearest_them(sapling, kept):
    skeleton, lod0 = sapling
    labels = twig_labels(skeleton, kept, None)
    cards = twig_cards(skeleton, lod0, labels, 2)
    face_label = labels[np.asarray(lod0.bark.attributes["branch"])[lod0.bark.faces[cards.bark_faces, 0]]]
    card_label = np.full(len(cards), -1)
    card_label[cards.bark_card] = face_label
    assert len(cards) <= 2 * (labels.max() + 1)
    # Both planes of a cluster cross on its principal axis, at right angles.
    pairs = [np.flatnonzero(card_label == label) for label in range(labels.max() + 1)]
    pairs = [pair for pair in pairs if len(pair) == 2]
    assert len(pairs) > 10
    for a, b in pairs:
        assert np.allclose(np.abs(cards.axes[a, 0] @ cards.axes[b, 0]), 1.0, atol=1e-9)
        assert abs(cards.axes[a, 2] @ cards.axes[b, 2]) < 1e-9
    # A face drawn on one plane only lies nearer that plane than the other plane of its cluster.
    centroid = lod0.bark.vertices[lod0.bark.faces[cards.bark_faces]].mean(axis=1).astype(np.float64)
    single = np.bincount(cards.bark_faces)[cards.bark_faces] == 1
    partner = {a: b for pair in pairs for a, b in (pair, pair[::-1])}
    checked = 0
    for face, card in zip(np.flatnonzero(single), cards.bark_card[single]):
        if card not in partner:
            continue
        other = partner[card]
        own = abs((centroid[face] - cards.origin[card]) @ cards.axes[card, 2])
        far = abs((centroid[face] - cards.origin[other]) @ cards.axes[other, 2])
        assert own <= far + 1e-9
        checked += 1
    assert checked > 100


def test_four_planes_or_more_cross_upright_the_first_along_the_widest_spread_in_plan(sapling, kept):
    skeleton, lod0 = sapling
    labels = twig_labels(skeleton, kept, 0)
    cards = twig_cards(skeleton, lod0, labels, UPRIGHT_PLANES)
    assert UPRIGHT_PLANES > TWIG_CARD_PLANES
    assert np.allclose(cards.axes[:, 0], [0.0, 0.0, 1.0])  # every plane holds the vertical
    assert np.allclose(cards.axes[:, 2, 2], 0.0, atol=1e-12)  # so its normal is level
    crossed = twig_cards(skeleton, lod0, labels, TWIG_CARD_PLANES)
    assert not np.allclose(crossed.axes[:, 0], [0.0, 0.0, 1.0])  # fewer planes cross on the principal axis
    # The first plane of the largest cluster lies along the widest spread of its vertices seen from above.
    branch = np.asarray(lod0.bark.attributes["branch"])
    largest = np.bincount(labels[branch][labels[branch] >= 0]).argmax()
    plan = lod0.bark.vertices[labels[branch] == largest][:, :2].astype(np.float64)
    leaves = labels[skeleton.branch_id[np.asarray(lod0.leaves.attributes["node"])]] == largest
    plan = np.concatenate([plan, lod0.leaves.vertices[leaves][:, :2]])
    widest = np.linalg.eigh(np.cov(plan.T, bias=True))[1][:, 1]
    first = np.flatnonzero(cards.branch == np.flatnonzero(labels == largest).min())[0]
    assert abs(cards.axes[first, 1, :2] @ widest) == pytest.approx(1.0, abs=1e-6)
    # Its planes are 180 / 4 deg apart about the vertical.
    planes = cards.axes[cards.branch == cards.branch[first]]
    turns = (np.degrees(np.arctan2(planes[:, 1, 1], planes[:, 1, 0])) - np.degrees(
        np.arctan2(planes[0, 1, 1], planes[0, 1, 0]))) % 45.0
    assert len(planes) >= 2 and np.minimum(turns, 45.0 - turns).max() < 1e-6


def test_a_crossed_pair_lying_about_level_stands_upright_the_others_keep_their_principal_axis(sapling, kept):
    skeleton, lod0 = sapling
    labels = twig_labels(skeleton, kept, None)
    cards = twig_cards(skeleton, lod0, labels, 2)
    bark_label = labels[np.asarray(lod0.bark.attributes["branch"])]
    leaf_label = labels[skeleton.branch_id[np.asarray(lod0.leaves.attributes["node"])]]
    counts = {"upright": 0, "principal": 0}
    for label in range(labels.max() + 1):
        points = np.concatenate([lod0.bark.vertices[bark_label == label], lod0.leaves.vertices[leaf_label == label]])
        spread, axes = np.linalg.eigh(np.cov(points.astype(np.float64).T, bias=True))
        if spread[1] - spread[0] < 1e-6 * spread[2] or spread[2] - spread[1] < 1e-6 * spread[2]:
            continue  # no clear least or principal axis: either frame would do
        own = cards.axes[cards.branch == np.flatnonzero(labels == label).min()]
        if abs(axes[2, 0]) > LEVEL_SPRAY_NORMAL_Z:
            assert np.allclose(own[:, 0], [0.0, 0.0, 1.0])
            counts["upright"] += 1
        else:
            assert np.allclose(np.abs(own[:, 0] @ axes[:, 2]), 1.0, atol=1e-6)
            counts["principal"] += 1
    assert counts["upright"] > 0 and counts["principal"] > 0


@pytest.mark.parametrize("planes", [0, 9, True, 1.5])
def test_plane_counts_out_of_range_are_refused(sapling, kept, planes):
    skeleton, lod0 = sapling
    with pytest.raises(TwigCardError, match="twig card planes"):
        twig_cards(skeleton, lod0, twig_labels(skeleton, kept, None), planes)


def test_atlas_tiles_do_not_overlap_and_map_back_to_the_card(sapling, kept):
    skeleton, lod0 = sapling
    cards = twig_cards(skeleton, lod0, twig_labels(skeleton, kept, None))
    atlas = TwigAtlas.pack([cards], [0.01], 64 * 64 * 64)
    index = atlas.card_index
    assert index.shape == (atlas.size[1], atlas.size[0])
    tiles = np.bincount(index[index >= 0], minlength=len(cards))
    expected = np.prod(np.ceil(cards.extent / atlas.texel[:, None]) + 2 * TWIG_PADDING_TEXELS, axis=1)
    assert np.array_equal(tiles, expected)  # each tile whole: none painted over another
    rng = np.random.default_rng(0)
    card = rng.integers(0, len(cards), 50)
    points = cards.origin[card] + rng.random((50, 1)) * cards.extent[card, :1] * cards.axes[card, 0] \
        + rng.random((50, 1)) * cards.extent[card, 1:] * cards.axes[card, 1]
    placed = atlas.to_atlas(points, card)
    assert np.allclose(atlas.from_atlas(placed[:, :2] + 0.5, card), points, atol=1e-9)


def test_a_texel_budget_coarsens_each_level_by_the_cube_root_of_its_texel_and_area(sapling, kept):
    skeleton, lod0 = sapling
    cards = twig_cards(skeleton, lod0, twig_labels(skeleton, kept, None))
    n = len(cards)
    fine, coarse = 0.001, 0.05

    def padded(texel):  # the texels the budget counts
        return (np.prod(cards.extent[None] / texel.reshape(2, -1)[..., None] + 2 * TWIG_PADDING_TEXELS,
                        axis=2)).sum()

    # Two levels of cards of the same sizes (moved aside: the same cards would share their tiles).
    moved = dataclasses.replace(cards, origin=cards.origin + 1.0)
    # A budget both levels must give way to: the same areas, so texels in proportion to the asked texel^(1/3).
    tight = 4_000
    atlas = TwigAtlas.pack([cards, moved], [fine, coarse], tight)
    near, far = atlas.texel[:n], atlas.texel[n:]
    assert np.ptp(near) == 0 and np.ptp(far) == 0  # one texel per level
    assert near[0] > fine and far[0] > coarse
    assert far[0] / near[0] == pytest.approx((coarse / fine) ** (1 / 3), rel=1e-9)
    assert tight * 0.999 <= padded(atlas.texel) <= tight  # the least coarsening that fits
    # A looser one: the far level is already coarse enough and keeps its texels; the near one gives way alone.
    loose = 20_000
    atlas = TwigAtlas.pack([cards, moved], [fine, coarse], loose)
    assert np.allclose(atlas.texel[n:], coarse) and (atlas.texel[:n] > fine).all()
    assert loose * 0.999 <= padded(atlas.texel) <= loose
    assert atlas.size[0] * atlas.size[1] <= 2 * loose
    # Nothing changes where the tiles fit.
    roomy = TwigAtlas.pack([cards, moved], [fine * 1000, coarse], 10 ** 9)
    assert np.allclose(roomy.texel[:n], fine * 1000) and np.allclose(roomy.texel[n:], coarse)


def test_a_card_every_level_draws_samples_the_nearest_level_s_tile_and_takes_no_texels_of_its_own(sapling, kept):
    skeleton, lod0 = sapling
    cards = twig_cards(skeleton, lod0, twig_labels(skeleton, kept, None))
    n, budget = len(cards), 6_000
    alone = TwigAtlas.pack([cards], [0.001], budget)
    # A farther level of the same cards and a few of its own (moved aside): only those take tiles.
    extra = dataclasses.replace(cards, origin=cards.origin + 1.0)
    both = TwigAtlas.pack([cards, _joined(cards, extra, 3)], [0.001, 0.002], budget)
    assert np.array_equal(both.source[:n], np.arange(n)) and np.array_equal(both.source[n:2 * n], np.arange(n))
    assert np.array_equal(both.source[2 * n:], np.arange(2 * n, 2 * n + 3))
    assert np.array_equal(both.texel[n:2 * n], both.texel[:n]) and np.array_equal(both.offset[n:2 * n], both.offset[:n])
    # The budget holds the tiles drawn: the near level gives way to three more cards, not to a second copy.
    unshared = TwigAtlas.pack([cards, _joined(extra, extra, 3)], [0.001, 0.002], budget)
    assert alone.texel[0] <= both.texel[0] < unshared.texel[0]
    own = both.source == np.arange(len(both.source))
    padded = np.prod(np.concatenate([cards.extent, cards.extent, extra.extent[:3]])[own] / both.texel[own, None]
                     + 2 * TWIG_PADDING_TEXELS, axis=1).sum()  # as the budget counts them (before rounding up)
    assert budget * 0.999 <= padded <= budget
    index = both.card_index
    assert set(np.unique(index[index >= 0])) == set(range(n)) | {2 * n, 2 * n + 1, 2 * n + 2}
    # A shared card's corners map into its source's tile as the source's do.
    assert np.allclose(both.card_part(1).uvs[:4 * n], both.card_part(0).uvs)
    # Three levels each twice as coarse: the farthest would sample four times finer than it asked, so it gets
    # tiles of its own, which the middle level (sharing the nearest's) cannot lend it.
    three = TwigAtlas.pack([cards, cards, cards], [0.001, 0.002, 0.004], 10 ** 9)
    assert np.array_equal(three.source, np.concatenate([np.arange(n), np.arange(n), np.arange(2 * n, 3 * n)]))
    assert np.allclose(three.texel, np.repeat([0.001, 0.001, 0.004], n))
    # Cards with the same frames but other faces (cards 0 and 1's bark swapped) are not shared.
    relabel = np.where(cards.bark_card == 0, 1, np.where(cards.bark_card == 1, 0, cards.bark_card))
    swapped = TwigAtlas.pack([cards, dataclasses.replace(cards, bark_card=relabel)], [0.001, 0.002], budget)
    assert np.array_equal(swapped.source[n:], np.concatenate([[n, n + 1], np.arange(2, n)]))


def _joined(first, second, count: int):
    """`first`'s cards followed by the first `count` of `second`'s (faces renumbered to their cards)."""
    def faces(kind):
        f, c = getattr(second, f"{kind}_faces"), getattr(second, f"{kind}_card")
        return (np.concatenate([getattr(first, f"{kind}_faces"), f[c < count]]),
                np.concatenate([getattr(first, f"{kind}_card"), c[c < count] + len(first)]))

    (bark, bark_card), (leaf, leaf_card) = faces("bark"), faces("leaf")
    return type(first)(*(np.concatenate([getattr(first, name), getattr(second, name)[:count]])
                         for name in ("origin", "axes", "extent", "branch")), bark, bark_card, leaf, leaf_card,
                       first.planes)


def test_a_twig_level_keeps_the_fallback_bark_to_its_share_and_draws_the_rest_as_cards(sapling):
    skeleton, lod0 = sapling
    lods = TreeLods(skeleton, lod0)
    share = 0.5 * lod0.bark.n_faces / lod0.n_faces
    plain = lods.build(3, 0.04, 128, bark_share=share)
    target = next(key[1] for key in lods.barks if key[3] == share)
    assert next(fit[4] for key, fit in lods.barks.items() if key[3] == share)  # no screen tolerance fitted
    assert plain.mesh.bark.n_faces > share * target  # the plain fallback takes the cards' room
    twigs = lods.build(3, 0.04, 128, bark_share=share, twigs=True)
    assert twigs.mesh.bark.n_faces <= share * target < plain.mesh.bark.n_faces
    assert len(twigs.twigs) > 0 and twigs.n_triangles <= target
    # The trunk is kept; every branch it drops is on a card.
    assert 0 in twigs.original_node
    kept = np.zeros(skeleton.n_branches, bool)
    kept[skeleton.branch_id[twigs.original_node]] = True
    dropped_bark = np.flatnonzero(~kept[np.asarray(lod0.bark.attributes["branch"])[lod0.bark.faces[:, 0]]])
    assert np.array_equal(np.unique(twigs.twigs.bark_faces), dropped_bark)


def _clusters(cards) -> int:
    return len(np.unique(cards.branch))  # every plane of a cluster grows from its branch nearest the trunk


def test_more_planes_where_the_room_holds_them_and_planes_first_on_coarser_clusters(sapling, kept):
    skeleton, lod0 = sapling
    lods = TreeLods(skeleton, lod0)
    finest = int(twig_labels(skeleton, kept, None).max()) + 1
    room = 2 * 2 * finest * 3  # three crossed pairs per cluster at the finest depth
    crossed = lods.twig_cards(kept, room)
    assert crossed.planes == 2 and len(crossed) <= 2 * finest
    spread = lods.twig_cards(kept, room, max_planes=8)
    assert spread.planes == 6 and _clusters(spread) == _clusters(crossed) and len(spread) <= room // 2
    # Planes first: 8 per cluster, on clusters coarse enough to take them.
    first = lods.twig_cards(kept, room, max_planes=8, planes_first=True)
    assert first.planes == 8 and len(first) <= room // 2
    assert _clusters(first) <= room // (2 * 8) < finest
    # Too little room for 8 planes per dropped subtree: the next halving that fits.
    subtrees = int(twig_labels(skeleton, kept, 0).max()) + 1
    assert lods.twig_cards(kept, 2 * 4 * subtrees, max_planes=8, planes_first=True).planes == 4


def test_a_far_level_of_more_planes_does_not_coarsen_the_nearer_ones(sapling, kept):
    skeleton, lod0 = sapling
    labels = twig_labels(skeleton, kept, None)
    near, far = twig_cards(skeleton, lod0, labels, 2), twig_cards(skeleton, lod0, twig_labels(skeleton, kept, 0), 8)
    crossed_far = twig_cards(skeleton, lod0, twig_labels(skeleton, kept, 0), 2)
    alone = TwigAtlas.pack([near], [0.002], 20_000)
    assert (alone.texel > 0.002).all()  # the budget binds
    with_far = TwigAtlas.pack([near, far], [0.002, 0.008], 20_000)
    assert np.allclose(with_far.texel[:len(near)], alone.texel)
    assert np.allclose(with_far.texel[len(near):], 0.008)
    # Two planes at the far level share the budget as before.
    shared = TwigAtlas.pack([near, crossed_far], [0.002, 0.008], 20_000)
    assert (shared.texel[:len(near)] > alone.texel[0]).all()


def test_bark_cards_hold_the_dropped_bark_alone_framed_by_it(sapling, kept):
    skeleton, lod0 = sapling
    labels = twig_labels(skeleton, kept, None)
    with_leaves, bark = twig_cards(skeleton, lod0, labels, 2), twig_cards(skeleton, lod0, labels, 2, leaves=False)
    assert with_leaves.leaves and len(with_leaves.leaf_faces) > 0
    assert not bark.leaves and len(bark.leaf_faces) == len(bark.leaf_card) == 0
    dropped_bark = np.flatnonzero(~kept[np.asarray(lod0.bark.attributes["branch"])[lod0.bark.faces[:, 0]]])
    assert np.array_equal(np.unique(bark.bark_faces), dropped_bark)
    # Each card spans its bark only (plus the margin), so it is no larger than the card that carried the leaves.
    only_bark = dataclasses.replace(lod0, leaves=species.MeshPart.empty())
    alone = twig_cards(skeleton, only_bark, labels, 2)
    assert np.allclose(bark.origin, alone.origin) and np.allclose(bark.extent, alone.extent)
    assert bark.extent.prod(axis=1).sum() < with_leaves.extent.prod(axis=1).sum()


def test_bark_cards_and_many_planes_come_on_top_of_the_atlas_budget_and_the_rest_ask_two_texels_a_pixel(sapling,
                                                                                                       kept):
    skeleton, lod0 = sapling
    labels = twig_labels(skeleton, kept, None)
    leafy, bark = twig_cards(skeleton, lod0, labels, 2), twig_cards(skeleton, lod0, labels, 2, leaves=False)
    many = twig_cards(skeleton, lod0, twig_labels(skeleton, kept, 0), 8)
    middle = twig_cards(skeleton, lod0, labels, BUDGETED_MAX_PLANES)  # a middle level's upright clusters
    assert leafy.budgeted and middle.budgeted and not bark.budgeted and not many.budgeted
    assert middle.planes == BUDGETED_MAX_PLANES < many.planes
    assert leafy.asked_texel(0.01) == pytest.approx(0.01 / BUDGETED_TEXELS_PER_PIXEL)
    assert bark.asked_texel(0.01) == many.asked_texel(0.01) == 0.01
    alone = TwigAtlas.pack([leafy], [0.002], 20_000)
    assert (alone.texel > 0.002).all()  # the budget binds
    both = TwigAtlas.pack([bark, leafy], [0.002, 0.002], 20_000)
    assert np.allclose(both.texel[:len(bark)], 0.002)  # bark cards keep their texel, whatever the budget
    assert np.allclose(both.texel[len(bark):], alone.texel)  # and take nothing from the others


def test_a_bark_card_level_draws_every_leaf_as_a_card_of_its_own_where_the_budget_holds_them(sapling):
    skeleton, lod0 = sapling
    lods = TreeLods(skeleton, lod0)
    share = 0.125 * lod0.bark.n_faces / lod0.n_faces
    level = lods.build(1, 0.4, 512, bark_share=share, twigs=True, twig_leaves=False)
    target = int(np.floor(0.97 * 0.4 * lod0.n_faces))
    assert not level.twigs.leaves and len(level.twigs.leaf_faces) == 0
    assert 0 < level.n_triangles <= target
    # Every leaf is a card (its own, not merged): the cards' leaves are LOD0's leaves.
    assert level.n_clusters == skeleton.n_leaves
    assert not level.mesh.leaves.attributes["clump"].any()
    assert np.allclose(np.sort(level.skeleton.leaves.reshape(len(level.skeleton.leaves), -1), axis=0),
                       np.sort(skeleton.leaves.reshape(skeleton.n_leaves, -1).astype(np.float32), axis=0))
    # Cards carrying the leaves draw them on the twig cards instead, and only the kept branches' leaves as cards.
    leafy = lods.build(1, 0.4, 512, bark_share=share, twigs=True)
    assert leafy.twigs.leaves and len(leafy.twigs.leaf_faces) > 0 and leafy.n_clusters < skeleton.n_leaves
    # Too little room for a card per leaf: the twig cards get at most half of what the bark leaves.
    tight = lods.build(2, 0.12, 256, bark_share=share, twigs=True, twig_leaves=False)
    room = int(np.floor(0.97 * 0.12 * lod0.n_faces)) - tight.mesh.bark.n_faces
    assert tight.n_clusters < skeleton.n_leaves and 2 * 2 * len(tight.twigs) <= room + 1
