"""Levels of detail fitted to the tree they simplify: each level's triangle budget is split between bark and leaf
cards in the proportion whose silhouette comes closest to LOD0's, seen from azimuths the quality figures never use.

In: skeleton, LOD0 TreeMesh and its coverage tree, the spec's budgets and switch sizes, the process's
CoverageRenderer, the opaque shares of a single-leaf card and of a clump card. Out: one
`species.studio.lod.LodLevel` per budget.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from renderers.alpha_coverage import coverage_tree
from renderers.framing import framing_points
from renderers.impostor import closed_silhouette, silhouette_iou, switch_camera
from renderers.twig_atlas import render_twig_atlas, twig_atlas_texels
from species.studio.leaf_clusters import CLUSTER_AREA_GAIN
from species.studio.lod import LodBudgetError, TreeLods, metres_per_pixel
from species.studio.twig_cards import TWIG_CARD_PLANES, TwigAtlas
from species.tree_mesh import MeshPart, TreeMesh

__all__ = ["fit_lods", "fit_impostor", "IMPOSTOR_GROWTHS", "IMPOSTOR_CALIBRATION_AZIMUTHS", "FittedLevel", "settle_twigs", "level_cover", "drawn_cover", "BARK_SHARE_SCALES", "CARD_AREA_GAINS", "CALIBRATION_AZIMUTHS",
           "TWIG_CALIBRATION_AZIMUTHS"]

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
# (renderers.impostor.QUALITY_AZIMUTHS) and the impostor's planes, so the reported IoU stays a fair test. One view
# chooses the shares two perpendicular ones would, for less (docs/library.md).
CALIBRATION_AZIMUTHS = (33.75,)
# A twig card shows its branches as they lie from its front and pressed flat from the side, so a level with twig
# cards is judged from two perpendicular azimuths (the first as above, then 90 deg on; both 22.5 deg off the
# quality ones): from one, a level whose cards face that view wins and loses elsewhere (lsystem_fractal_plant's
# LOD3: .765 from 33.75 deg, .383 from the worst quality azimuth).
TWIG_CALIBRATION_AZIMUTHS = tuple(CALIBRATION_AZIMUTHS[0] + 90.0 * k for k in range(2))
# The farthest level's twig cards may have up to this many planes per cluster (its few clusters are whole
# subtrees, seen from between two planes), and two rules are tried there: the crossed pairs at the finest depth
# with more planes where the room allows, and as many planes as fit on coarser clusters; the calibration keeps the
# better (45 presets, mean least LOD3 IoU .769 -> .778, sc_multistem_shrub .69 -> .80, sc_spruce .70 -> .77; with
# planes first alone, sc_cypress_column fell .60 -> .50; docs/library.md).
FAR_TWIG_PLANES = 8
# Twig rules a level is fitted with: (max planes, planes first) for nearer levels, then for the farthest.
_NEAR_TWIG_RULES = ((TWIG_CARD_PLANES, False),)
_FAR_TWIG_RULES = ((FAR_TWIG_PLANES, False), (FAR_TWIG_PLANES, True))
# The crossed impostor's alpha as rendered, or grown by a texel: whichever matches LOD0 better from
# IMPOSTOR_CALIBRATION_AZIMUTHS at the impostor's switch size (ties: as rendered). Grown suits sparse,
# thin-branched plants whose twigs fall between the texels a pixel samples and fattens dense crowns, so it is chosen
# per asset (least IoU at 64 px over the quality azimuths: lsystem_dichotomous .336 -> .431, sc_sympodial_lilac
# .855 -> .884 grown; grown everywhere, bonsai .809 -> .762, balsam_fir .440 -> .254; docs/library.md). Four views,
# 45 deg apart and 22.5 deg off the quality ones: from the two twig views, lsystem_abop_tree (.799 -> .783) and
# sc_excurrent_leader (.399 -> .364) were grown for a calibration gain of .015 and .012.
IMPOSTOR_GROWTHS = (0, 1)
IMPOSTOR_CALIBRATION_AZIMUTHS = tuple(CALIBRATION_AZIMUTHS[0] + 45.0 * k for k in range(4))


@dataclass(frozen=True, eq=False)
class FittedLevel:
    """One level's two fitted candidates and what they were judged by.

    plain, plain_score : the best level without twig cards and its least IoU from TWIG_CALIBRATION_AZIMUTHS
                         (-1.0 when there is no twig candidate to compare it with).
    twigs, twig_score  : the best level with twig cards (None, -1.0 when none could be built), scored from the
                         same azimuths with exact card textures.
    switch_px, cameras, references : the level's switch size, the cameras of TWIG_CALIBRATION_AZIMUTHS and
                         LOD0's closed silhouettes through them.
    """

    plain: object
    plain_score: float
    twigs: object
    twig_score: float
    switch_px: int
    cameras: list
    references: list


def fit_lods(skeleton, lod0, lod0_cover, budgets, switch_px, renderer, leaf_fraction: float,
             card_fraction: float, points=None) -> list[FittedLevel]:
    """One FittedLevel per (budget, switch size), fitted against LOD0 at the level's switch size from
    CALIBRATION_AZIMUTHS (score: the least IoU over them). First the bark share climbs BARK_SHARE_SCALES x LOD0's
    share from the previous level's choice (LOD1: _FIRST_SCALE) to the better neighbour while one is better; then,
    from LOD2 on, at that share, the cluster cards' area gain climbs CARD_AREA_GAINS from the default the same
    way. Then the bark share climbs again, from there, with the dropped branches drawn as twig cards (scored as
    `level_cover` draws them: exact card textures; at the farthest level once per rule of _FAR_TWIG_RULES, the
    best kept); `settle_twigs` makes the final choice once the atlas exists. A level costs six to twelve builds
    (the farthest up to about twenty), not one per pair. Budgets LOD0's own proportion cannot meet raise
    LodBudgetError as `build_lod` does; other shares that cannot be met are skipped. `points`: LOD0's
    `framing_points`, when the caller has them."""
    lods = TreeLods(skeleton, lod0)
    lod0_share = lod0.bark.n_faces / max(lod0.n_faces, 1)
    points = framing_points(lod0) if points is None else points
    full_share = BARK_SHARE_SCALES.index(1.0)
    default_gain = CARD_AREA_GAINS.index(CLUSTER_AREA_GAIN)
    start = BARK_SHARE_SCALES.index(_FIRST_SCALE)
    levels = []
    for level, (budget, px) in enumerate(zip(budgets, switch_px), 1):
        px = int(px)
        views = {azimuth: switch_camera(points, azimuth, px) for azimuth in TWIG_CALIBRATION_AZIMUTHS}
        references = {azimuth: closed_silhouette(renderer.coverage(lod0_cover, camera))
                      for azimuth, camera in views.items()}
        tried: dict[tuple[int, int, bool], tuple[float, object]] = {}

        def judged(lod, azimuths) -> float:
            cover = level_cover(lod, lod0_cover, leaf_fraction, card_fraction)
            return min(silhouette_iou(references[a], closed_silhouette(renderer.coverage(cover, views[a])))
                       for a in azimuths)

        rules = _FAR_TWIG_RULES if level == len(budgets) else _NEAR_TWIG_RULES

        def score(share: int, gain: int, twigs: int = 0) -> float:
            """twigs: 0 plain, k > 0 twig cards by rules[k - 1]."""
            if (share, gain, twigs) not in tried:
                scale = BARK_SHARE_SCALES[share]
                try:
                    bark_share = None if share == full_share else min(scale * lod0_share, 1.0)
                    max_planes, planes_first = rules[twigs - 1] if twigs else (TWIG_CARD_PLANES, False)
                    lod = lods.build(level, budget, px, bark_share=bark_share, card_area_gain=CARD_AREA_GAINS[gain],
                                     twigs=bool(twigs), twig_planes=max_planes, planes_first=planes_first)
                except LodBudgetError:
                    if share == full_share and not twigs:
                        raise  # LOD0's own proportion is the reference: its failure is the budget's
                    tried[share, gain, twigs] = (-1.0, None)
                    return -1.0
                tried[share, gain, twigs] = (judged(lod, TWIG_CALIBRATION_AZIMUTHS if twigs else CALIBRATION_AZIMUTHS),
                                             lod)
            return tried[share, gain, twigs][0]

        share = _climb(lambda index: score(index, default_gain), start, len(BARK_SHARE_SCALES))
        if tried[share, default_gain, 0][1] is None:  # nothing but LOD0's proportion could be built
            score(full_share, default_gain)
            share = full_share
        gain = default_gain
        if level >= _FIRST_GAIN_LEVEL:
            gain = _climb(lambda index: score(share, index), default_gain, len(CARD_AREA_GAINS))
        plain = tried[share, gain, 0][1]
        # Twig cards look different from every side: both candidates are compared from all the twig azimuths. The
        # twig climb runs only when cards at the plain level's share already beat it (on most Weber-Penn crowns they
        # do not, and each candidate of a large tree costs more than the plain climb: with a climb from every
        # level the median asset took about 1.3 s instead of 0.7).
        # Where the plain level's bark takes the whole budget, the cards start from the largest share that leaves
        # them room (weeping_willow's LOD3: plain .50 at 1.0, cards .84 at 0.125). Each twig rule climbs on its
        # own; the best-scoring is the level's twig candidate. A later rule is tried only where the first one's
        # cards beat the plain level (on a dense Weber-Penn crown they do not, and a large tree's candidate costs
        # about a second: cherry's lods 2.6 -> 3.8 s when every rule ran).
        plain_score, twig_score, twig_lod = -1.0, -1.0, None
        for rule in range(1, len(rules) + 1):
            if rule > 1 and twig_score <= plain_score:
                break
            twig_share = share
            while twig_share > 0 and score(twig_share, default_gain, rule) < 0.0:
                twig_share -= 1
            if score(twig_share, default_gain, rule) >= 0.0:
                if plain_score < 0.0:
                    plain_score = judged(plain, TWIG_CALIBRATION_AZIMUTHS)
                if score(twig_share, default_gain, rule) > plain_score:
                    twig_share = _climb(lambda index, rule=rule: score(index, default_gain, rule), twig_share,
                                        len(BARK_SHARE_SCALES))
            if tried[twig_share, default_gain, rule][0] > twig_score:
                twig_score, twig_lod = tried[twig_share, default_gain, rule]
        levels.append(FittedLevel(plain, plain_score, twig_lod, twig_score, px,
                                  [views[a] for a in TWIG_CALIBRATION_AZIMUTHS],
                                  [references[a] for a in TWIG_CALIBRATION_AZIMUTHS]))
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


def _with_faces(cover: TreeMesh, bark: MeshPart, leaves: MeshPart | None = None) -> TreeMesh:
    """`cover` with more faces drawn as bark and, when given, as leaves (coverage passes draw both alike)."""
    return dataclasses.replace(cover, bark=MeshPart.concatenate([cover.bark, bark]),
                               leaves=cover.leaves if leaves is None else MeshPart.concatenate([cover.leaves, leaves]))


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
                                [metres_per_pixel(skeleton, fitted[k].switch_px) for k in chosen],
                                twig_atlas_texels(lod0_cover.n_faces))
        image = render_twig_atlas(renderer, layout, lod0_cover)
        losing = []
        for index, k in enumerate(chosen):
            level = fitted[k]
            cover = drawn_cover(level.twigs.mesh, leaf_fraction, card_fraction, image.opaque_runs(index))
            drawn = min(silhouette_iou(reference, closed_silhouette(renderer.coverage(cover, camera)))
                        for reference, camera in zip(level.references, level.cameras))
            if drawn <= level.plain_score:
                losing.append(k)
        if not losing:
            slots = [chosen.index(k) if k in chosen else -1 for k in range(len(fitted))]
            return [f.twigs if k in chosen else f.plain for k, f in enumerate(fitted)], image, slots
        for k in losing:
            use[k] = False


def _climb(score, start: int, count: int) -> int:
    """The index in [0, count) reached from `start` by moving to the better-scoring neighbour while one scores
    higher (strictly: ties stay)."""
    best = start
    while True:
        better = [i for i in (best - 1, best + 1) if 0 <= i < count and score(i) > score(best)]
        if not better:
            return best
        best = max(better, key=score)


def fit_impostor(atlas, points, lod0_cover: TreeMesh, renderer, switch_px: int):
    """The crossed impostor `atlas` with its alpha grown by the IMPOSTOR_GROWTHS step that scores best against
    LOD0 (`lod0_cover` drawn, framed by LOD0's `framing_points`) from IMPOSTOR_CALIBRATION_AZIMUTHS at
    `switch_px`."""
    cameras = [switch_camera(points, azimuth, int(switch_px)) for azimuth in IMPOSTOR_CALIBRATION_AZIMUTHS]
    references = [closed_silhouette(renderer.coverage(lod0_cover, camera)) for camera in cameras]
    best, best_score = atlas, -1.0
    for texels in IMPOSTOR_GROWTHS:
        candidate = atlas.grown(texels) if texels else atlas
        found = min(silhouette_iou(reference, closed_silhouette(candidate.coverage(camera)))
                    for reference, camera in zip(references, cameras))
        if found > best_score:
            best, best_score = candidate, found
    return best
