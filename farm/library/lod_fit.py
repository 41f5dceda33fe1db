"""Levels of detail fitted to the tree they simplify: each level's triangle budget is split between bark and leaf
cards in the proportion whose silhouette comes closest to LOD0's, seen from azimuths the quality figures never use.

In: skeleton, LOD0 TreeMesh and its coverage tree, the spec's budgets and switch sizes, the process's
CoverageRenderer, the opaque shares of a single-leaf card and of a clump card. Out: one
`species.studio.lod.LodLevel` per budget.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from renderers.alpha_coverage import coverage_tree
from renderers.framing import framing_points
from renderers.impostor import AXIS_SHARE
from renderers.silhouette_metric import closed_silhouette, silhouette_iou, switch_camera
from renderers.twig_atlas import render_twig_atlas, twig_atlas_texels
from species.studio.leaf_clusters import CLUSTER_AREA_GAIN
from species.studio.lod import LodBudgetError, TreeLods, metres_per_pixel
from species.studio.twig_cards import TWIG_CARD_PLANES, TwigAtlas
from species.tree_mesh import MeshPart, TreeMesh

__all__ = ["fit_lods", "fit_impostor", "TwigRule", "CalibrationViews", "Judgement", "climb_ladder",
           "IMPOSTOR_GROWTHS", "IMPOSTOR_AXIS_SHARES", "IMPOSTOR_CALIBRATION_AZIMUTHS", "FittedLevel",
           "settle_twigs", "level_cover", "drawn_cover", "BARK_SHARE_SCALES", "CARD_AREA_GAINS",
           "CALIBRATION_AZIMUTHS", "TWIG_CALIBRATION_AZIMUTHS", "MIDDLE_TWIG_PLANES"]

# Candidate bark shares of a level's budget, as multiples of LOD0's bark share (at most the whole budget but one
# card). A simplified branch draws more silhouette per triangle than a merged leaf card on a sparse crown and less
# on a dense one, and leaf cards gain on coarser levels, so no single proportion suits every tree and level: the
# ladder reaches below and above LOD0's own share (docs/library.md gives the shares the presets choose).
BARK_SHARE_SCALES = (0.125, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)
# Where the search starts on that ladder for LOD1; each coarser level starts where the one before ended.
_FIRST_SCALE = 0.75
# Candidate area gains of the cluster cards (species.studio.leaf_clusters.CLUSTER_AREA_GAIN is the default): how
# much of the gap between a cluster's leaves its card fills depends on how many pixels the leaves span at the
# switch size.
CARD_AREA_GAINS = (0.75, 1.0, 1.5, 2.25, 3.5)
# Levels from which the gain is fitted: at LOD1's size the leaves span several pixels and the default suits, so
# fitting it there gains little for its cost (docs/library.md has the figures).
_FIRST_GAIN_LEVEL = 2
# Azimuths (degrees) the split is judged from: 22.5 deg off both the quality azimuths
# (renderers.silhouette_metric.QUALITY_AZIMUTHS) and the impostor's planes, so the reported IoU stays a fair test.
# One view chooses the shares two perpendicular ones would, for less (docs/library.md).
CALIBRATION_AZIMUTHS = (33.75,)
# A twig card shows its branches as they lie from its front and pressed flat from the side, so a level with twig
# cards is judged from two perpendicular azimuths (the first as above, then 90 deg on; both 22.5 deg off the
# quality ones): from one, a level whose cards face that view wins and loses elsewhere (a flat spray seen edge-on
# from the worst quality azimuth).
TWIG_CALIBRATION_AZIMUTHS = tuple(CALIBRATION_AZIMUTHS[0] + 90.0 * k for k in range(2))
# The farthest level's twig cards may have up to this many planes per cluster (its few clusters are whole
# subtrees, seen from between two planes), and two rules are tried there: the crossed pairs at the finest depth
# with more planes where the room allows, and as many planes as fit on coarser clusters; the calibration keeps the
# better: each rule wins on presets where the other loses (shrubs and spruces take the planes, tilted sprays the
# pairs; docs/library.md).
FAR_TWIG_PLANES = 8


class TwigRule(NamedTuple):
    """How a level's twig candidate is built (`TreeLods.build`): at most `planes` per cluster, as many planes as
    fit first (`planes_first`) or the finest clusters first, the cards carrying their branches' leaves or bark
    cards (`leaves` False)."""

    planes: int
    planes_first: bool = False
    leaves: bool = True


# The levels between the nearest and the farthest (LOD2 by default) may draw up to this many planes per cluster
# where the room holds them (crossed upright from twig_cards.UPRIGHT_PLANES), their tiles in the atlas budget
# (twig_cards.BUDGETED_MAX_PLANES): at 256 px a crossed pair shows a cluster's twigs pressed from between its
# planes, and a few more planes keep bushy clusters' width from every side (docs/library.md).
MIDDLE_TWIG_PLANES = 4
# Twig rules a level is fitted with, for the nearest level, the middle ones and the farthest. Bark cards (every
# dropped branch a crossed pair of its own bark, its leaves left as leaf cards, one per leaf where the budget
# holds them) suit the near levels of shrubs and saplings, whose tubes would take the budget and whose leaves
# lose their shape pressed onto cards (docs/library.md has what they gain). At the far level, bark cards won
# nowhere: its leaves would all be clumps.
_NEAR_TWIG_RULES = (TwigRule(TWIG_CARD_PLANES), TwigRule(TWIG_CARD_PLANES, leaves=False))
_MIDDLE_TWIG_RULES = (TwigRule(MIDDLE_TWIG_PLANES), TwigRule(TWIG_CARD_PLANES, leaves=False))
_FAR_TWIG_RULES = (TwigRule(FAR_TWIG_PLANES), TwigRule(FAR_TWIG_PLANES, planes_first=True))
# The crossed impostor's alpha as rendered, or grown by a texel: whichever matches LOD0 better from
# IMPOSTOR_CALIBRATION_AZIMUTHS at the impostor's switch size (ties: as rendered). Grown suits sparse,
# thin-branched plants whose twigs fall between the texels a pixel samples and fattens dense crowns, so it is chosen
# per asset (docs/library.md). Four views, 45 deg apart and 22.5 deg off the quality ones: the two twig views alone
# let a small calibration gain grow crowns that then lose from the quality azimuths.
IMPOSTOR_GROWTHS = (0, 1)
# And the share of the planes' half side about the axis drawn on every plane (renderers.impostor.AXIS_SHARE, or
# less): a narrow crown lies within 0.2 of it whole, so every plane would draw all of it and a view between planes
# would see it several times over. Chosen by the least plus the mean IoU over the calibration views: by the least
# alone, the choice follows one view's noise (docs/library.md).
IMPOSTOR_AXIS_SHARES = (AXIS_SHARE, 0.1)
IMPOSTOR_CALIBRATION_AZIMUTHS = tuple(CALIBRATION_AZIMUTHS[0] + 45.0 * k for k in range(4))


class CalibrationViews:
    """A level's calibration cameras (TWIG_CALIBRATION_AZIMUTHS at its switch size) and LOD0's closed silhouettes
    through them, each silhouette drawn when first needed."""

    def __init__(self, renderer, lod0_cover: TreeMesh, points, switch_px: int):
        self.renderer, self.lod0_cover, self.switch_px = renderer, lod0_cover, int(switch_px)
        self.cameras = [switch_camera(points, azimuth, self.switch_px) for azimuth in TWIG_CALIBRATION_AZIMUTHS]
        self._references: dict[int, object] = {}

    def iou(self, view: int, cover: TreeMesh) -> float:
        """Silhouette IoU of `cover` against LOD0 through camera `view`."""
        if view not in self._references:
            self._references[view] = closed_silhouette(self.renderer.coverage(self.lod0_cover, self.cameras[view]))
        found = closed_silhouette(self.renderer.coverage(cover, self.cameras[view]))
        return silhouette_iou(self._references[view], found)


class Judgement:
    """One candidate's least IoU over the first `views` calibration views, drawn a view at a time and only as far
    as a comparison needs: once the IoUs drawn fall to a score to beat, the rest cannot lift the least above it.
    `cover`: the candidate's coverage tree, or a callable making it (called on the first draw: a candidate never
    drawn is never made)."""

    def __init__(self, views: CalibrationViews, cover):
        self.views, self._cover, self.ious = views, cover, []

    def least(self, views: int, beat: float = -np.inf) -> float:
        """The least IoU over the first `views` views; with `beat`, it may stop early and return an upper bound
        of it that is at most `beat` (so a strict comparison with `beat` comes out as the full least's would)."""
        while len(self.ious) < views and min(self.ious, default=np.inf) > beat:
            if callable(self._cover):
                self._cover = self._cover()
            self.ious.append(self.views.iou(len(self.ious), self._cover))
        return min(self.ious[:views])


@dataclass(frozen=True, eq=False)
class FittedLevel:
    """One level's two fitted candidates and what they were judged by.

    plain, plain_score : the best level without twig cards and its least IoU from TWIG_CALIBRATION_AZIMUTHS
                         (-1.0 when there is no twig candidate to compare it with).
    twigs, twig_score  : the best level with twig cards (None, -1.0 when none could be built), scored from the
                         same azimuths with exact card textures; where they cannot beat `plain_score`, an upper
                         bound of their score that is at most `plain_score` (the views left undrawn).
    switch_px, views   : the level's switch size and its CalibrationViews.
    """

    plain: object
    plain_score: float
    twigs: object
    twig_score: float
    switch_px: int
    views: CalibrationViews


def fit_lods(skeleton, lod0, lod0_cover, budgets, switch_px, renderer, leaf_fraction: float,
             card_fraction: float, points=None, twig_cards: bool = True) -> list[FittedLevel]:
    """One FittedLevel per (budget, switch size), fitted against LOD0 at the level's switch size from
    CALIBRATION_AZIMUTHS (score: the least IoU over them). First the bark share climbs BARK_SHARE_SCALES x LOD0's
    share from the previous level's choice (LOD1: _FIRST_SCALE) to the better neighbour while one is better; then,
    from LOD2 on, at that share, the cluster cards' area gain climbs CARD_AREA_GAINS from the default the same
    way. Then the bark share climbs again, from there, with the dropped branches drawn as twig cards (scored as
    `level_cover` draws them: exact card textures; at the farthest level once per rule of _FAR_TWIG_RULES, the
    best kept); `settle_twigs` makes the final choice once the atlas exists. A level costs six to twelve builds
    (the farthest up to about twenty), not one per pair, and a candidate that cannot beat the one it is compared
    with is not drawn from its remaining views (`Judgement`). Budgets LOD0's own proportion cannot meet raise
    LodBudgetError as `build_lod` does; other shares that cannot be met are skipped. `points`: LOD0's
    `framing_points`, when the caller has them. `twig_cards=False`: the plain climbs only (every level's
    `twigs` None)."""
    lods = TreeLods(skeleton, lod0)
    lod0_share = lod0.bark.n_faces / max(lod0.n_faces, 1)
    points = framing_points(lod0) if points is None else points
    full_share = BARK_SHARE_SCALES.index(1.0)
    default_gain = CARD_AREA_GAINS.index(CLUSTER_AREA_GAIN)
    start = BARK_SHARE_SCALES.index(_FIRST_SCALE)
    levels = []
    for level, (budget, px) in enumerate(zip(budgets, switch_px), 1):
        px = int(px)
        views = CalibrationViews(renderer, lod0_cover, points, px)
        tried: dict[tuple[int, int, int], tuple[object, Judgement | None]] = {}
        rules = _FAR_TWIG_RULES if level == len(budgets) else _NEAR_TWIG_RULES if level == 1 else _MIDDLE_TWIG_RULES
        if not twig_cards:
            rules = ()

        def built(share: int, gain: int, twigs: int = 0):
            """The candidate level (None where it cannot be built); twigs: 0 plain, k > 0 twig cards by
            rules[k - 1]."""
            if (share, gain, twigs) not in tried:
                scale = BARK_SHARE_SCALES[share]
                try:
                    bark_share = None if share == full_share else min(scale * lod0_share, 1.0)
                    twig_rule = rules[twigs - 1] if twigs else TwigRule(TWIG_CARD_PLANES)
                    lod = lods.build(level, budget, px, bark_share=bark_share, card_area_gain=CARD_AREA_GAINS[gain],
                                     twigs=bool(twigs), twig_planes=twig_rule.planes,
                                     planes_first=twig_rule.planes_first, twig_leaves=twig_rule.leaves)
                except LodBudgetError:
                    if share == full_share and not twigs:
                        raise  # LOD0's own proportion is the reference: its failure is the budget's
                    tried[share, gain, twigs] = (None, None)
                    return None
                # Two rules may come to the same cards at a share (TreeLods keeps them by what they are: the far
                # level's rules, where its clusters are few): the same level, judged once.
                same = [entry for (s, g, t), entry in tried.items()
                        if t and t != twigs and s == share and g == gain and entry[0] is not None
                        and entry[0].twigs is lod.twigs]
                if same:
                    tried[share, gain, twigs] = same[0]
                else:
                    cover = lambda lod=lod: level_cover(lod, lod0_cover, leaf_fraction, card_fraction)  # noqa: E731
                    tried[share, gain, twigs] = (lod, Judgement(views, cover))
            return tried[share, gain, twigs][0]

        def score(share: int, gain: int, twigs: int = 0, beat: float = -np.inf) -> float:
            """The candidate's least IoU (-1.0 where it cannot be built): plain ones from CALIBRATION_AZIMUTHS,
            twig ones from TWIG_CALIBRATION_AZIMUTHS; at most `beat` where it cannot beat it (`Judgement`)."""
            if built(share, gain, twigs) is None:
                return -1.0
            count = len(TWIG_CALIBRATION_AZIMUTHS) if twigs else len(CALIBRATION_AZIMUTHS)
            return tried[share, gain, twigs][1].least(count, beat)

        share = climb_ladder(lambda index, beat=-np.inf: score(index, default_gain, beat=beat), start,
                             len(BARK_SHARE_SCALES))
        if built(share, default_gain) is None:  # nothing but LOD0's proportion could be built
            built(full_share, default_gain)  # raises where even that cannot be
            share = full_share
        gain = default_gain
        if level >= _FIRST_GAIN_LEVEL:
            gain = climb_ladder(lambda index, beat=-np.inf: score(share, index, beat=beat), default_gain,
                                len(CARD_AREA_GAINS))
        plain, plain_judgement = tried[share, gain, 0]
        # Twig cards look different from every side: both candidates are compared from all the twig azimuths. The
        # twig climb runs only when cards at the plain level's share already beat it (on most Weber-Penn crowns they
        # do not, and each candidate of a large tree costs more than the plain climb: a climb from every level
        # would cost far more time than it gains).
        # Where the plain level's bark takes the whole budget, the cards start from the largest share that leaves
        # them room (a weeping willow's LOD3 needs a small bark share); bark cards start from the
        # least share. Each twig rule climbs on its own; the best-scoring is the level's twig candidate. A later
        # rule is tried only where the first one's cards beat the plain level (on a dense Weber-Penn crown they do
        # not, and a large tree's candidate costs far more than its gain: bark cards tried there too gain little,
        # on presets already within their floors).
        plain_score, twig_score, twig_lod = -1.0, -1.0, None
        for rule in range(1, len(rules) + 1):
            if rule > 1 and twig_score <= plain_score:
                break
            if rules[rule - 1].leaves:
                twig_share = share
                while twig_share > 0 and built(twig_share, default_gain, rule) is None:
                    twig_share -= 1
            else:
                # Bark cards leave the bark little (a sapling's LOD1 scores far better near the least share than at
                # the plain level's).
                twig_share = 0
                while twig_share < share and built(twig_share, default_gain, rule) is None:
                    twig_share += 1
            if built(twig_share, default_gain, rule) is not None:
                if plain_score < 0.0:
                    plain_score = plain_judgement.least(len(TWIG_CALIBRATION_AZIMUTHS))
                if score(twig_share, default_gain, rule, beat=plain_score) > plain_score:
                    twig_share = climb_ladder(
                        lambda index, beat=-np.inf, rule=rule: score(index, default_gain, rule, beat), twig_share,
                        len(BARK_SHARE_SCALES))
            found = score(twig_share, default_gain, rule, beat=plain_score)
            if found > twig_score:
                twig_score, twig_lod = found, built(twig_share, default_gain, rule)
        levels.append(FittedLevel(plain, plain_score, twig_lod, twig_score, px, views))
        start = share
    return levels


def level_cover(lod, lod0_cover: TreeMesh, leaf_fraction: float, card_fraction: float) -> TreeMesh:
    """What a level shows, for opaque coverage passes: its tubes and leaf cards cut to their tiles' opaque share
    (`coverage_tree`), and its twig cards as LOD0's coverage faces pressed onto each card (an exact card texture,
    before it is sampled into the atlas)."""
    cover = coverage_tree(lod.mesh, leaf_fraction, card_fraction)
    if lod.twigs is None:
        return cover
    flat = lod.twigs.flattened(lod0_cover)
    return _with_faces(cover, flat.bark, flat.leaves)


def drawn_cover(lod_mesh: TreeMesh, leaf_fraction: float, card_fraction: float, twig_runs=None) -> TreeMesh:
    """What a built level shows, for opaque coverage passes: its tubes and leaf cards cut to their tiles' opaque
    share, and its twig cards as the atlas draws them (`TwigAtlasImage.opaque_runs`, when it has any)."""
    cover = coverage_tree(lod_mesh, leaf_fraction, card_fraction)
    return cover if twig_runs is None else _with_faces(cover, twig_runs)


def _with_faces(cover: TreeMesh, *parts: MeshPart) -> TreeMesh:
    """`cover` with more faces, drawn double-sided as its leaves are (twig cards and the faces pressed onto them
    are not closed: a coverage pass culls only the bark's back faces, as the files' bark material does)."""
    return dataclasses.replace(cover, leaves=MeshPart.concatenate([cover.leaves, *parts]))


def settle_twigs(fitted: list[FittedLevel], skeleton, lod0_cover: TreeMesh, renderer, leaf_fraction: float,
                 card_fraction: float):
    """The final levels and the twig atlas (None without twig levels). Levels whose twig candidate beat the plain
    one with exact textures get their cards into one atlas (`TwigAtlas.pack`, a texel per screen pixel at each
    switch size within `twig_atlas_texels`); each is judged again as the atlas draws it, and one that now loses
    to its plain candidate falls back to it, the atlas made again without it, until every twig level left wins.
    Returns (levels [LodLevel], twig atlas image, twig level index per level: -1 without cards)."""
    use = [f.twigs is not None and f.twig_score > f.plain_score for f in fitted]
    while True:
        chosen = [k for k, wanted in enumerate(use) if wanted]
        if not chosen:
            return [f.plain for f in fitted], None, [-1] * len(fitted)
        layout = TwigAtlas.pack([fitted[k].twigs.twigs for k in chosen],
                                [fitted[k].twigs.twigs.asked_texel(metres_per_pixel(skeleton, fitted[k].switch_px))
                                 for k in chosen],
                                twig_atlas_texels(lod0_cover.n_faces))
        image = render_twig_atlas(renderer, layout, lod0_cover)
        losing = []
        for index, k in enumerate(chosen):
            level = fitted[k]
            cover = drawn_cover(level.twigs.mesh, leaf_fraction, card_fraction, image.opaque_runs(index))
            drawn = Judgement(level.views, cover).least(len(TWIG_CALIBRATION_AZIMUTHS), beat=level.plain_score)
            if drawn <= level.plain_score:
                losing.append(k)
        if not losing:
            slots = [chosen.index(k) if k in chosen else -1 for k in range(len(fitted))]
            return [f.twigs if k in chosen else f.plain for k, f in enumerate(fitted)], image, slots
        for k in losing:
            use[k] = False


def climb_ladder(score, start: int, count: int) -> int:
    """The index in [0, count) reached from `start` by moving to the better-scoring neighbour while one scores
    higher (strictly: ties stay). `score(index, beat)` may return any value at most `beat` for an index that
    cannot beat it (`Judgement.least`); `score(index)` is the full score."""
    best = start
    while True:
        floor = score(best)
        better = [i for i in (best - 1, best + 1) if 0 <= i < count and score(i, floor) > floor]
        if not better:
            return best
        best = max(better, key=score)


def fit_impostor(render, points, lod0_cover: TreeMesh, renderer, switch_px: int):
    """The crossed impostor that matches LOD0 (`lod0_cover` drawn, framed by LOD0's `framing_points`) best from
    IMPOSTOR_CALIBRATION_AZIMUTHS at `switch_px`: the least plus the mean IoU over them, among the atlases
    `render(IMPOSTOR_AXIS_SHARES)` returns (one per share: sliced with that share of the planes' half side on every
    plane; `renderers.impostor.render_impostors` uploads the slices once for all), each with its alpha grown by
    each of IMPOSTOR_GROWTHS (ties: the first)."""
    cameras = [switch_camera(points, azimuth, int(switch_px)) for azimuth in IMPOSTOR_CALIBRATION_AZIMUTHS]
    references = [closed_silhouette(renderer.coverage(lod0_cover, camera)) for camera in cameras]
    best, best_score, first, pixels = None, -np.inf, None, None
    for atlas in render(IMPOSTOR_AXIS_SHARES):
        if first is None or not atlas.same_billboard(first):  # the candidates differ in alpha alone
            first, pixels = atlas, [atlas.billboard_pixels(camera) for camera in cameras]
        for texels in IMPOSTOR_GROWTHS:
            candidate = atlas.grown(texels) if texels else atlas
            ious = [silhouette_iou(reference, closed_silhouette(candidate.coverage_of(hits, camera)))
                    for reference, hits, camera in zip(references, pixels, cameras)]
            found = min(ious) + float(np.mean(ious))
            if found > best_score:
                best, best_score = candidate, found
    return best
