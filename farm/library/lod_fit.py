"""Levels of detail fitted to the tree they simplify: each level's triangle budget is split between bark and leaf
cards in the proportion whose silhouette comes closest to LOD0's, seen from azimuths the quality figures never use.

In: skeleton, LOD0 TreeMesh and its coverage tree, the spec's budgets and switch sizes, the process's
CoverageRenderer, the opaque shares of a single-leaf card and of a clump card. Out: one
`species.studio.lod.LodLevel` per budget.
"""
from __future__ import annotations

from renderers.alpha_coverage import coverage_tree
from renderers.framing import framing_points
from renderers.impostor import closed_silhouette, silhouette_iou, switch_camera
from species.studio.leaf_clusters import CLUSTER_AREA_GAIN
from species.studio.lod import LodBudgetError, TreeLods
from species.tree_mesh import MeshPart, TreeMesh

__all__ = ["fit_lods", "level_cover", "BARK_SHARE_SCALES", "CARD_AREA_GAINS", "CALIBRATION_AZIMUTHS"]

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


def fit_lods(skeleton, lod0, lod0_cover, budgets, switch_px, renderer, leaf_fraction: float,
             card_fraction: float) -> list:
    """One LodLevel per (budget, switch size), fitted against LOD0 at the level's switch size from
    CALIBRATION_AZIMUTHS (score: the least IoU over them). First the bark share climbs BARK_SHARE_SCALES x LOD0's
    share from the previous level's choice (LOD1: _FIRST_SCALE) to the better neighbour while one is better; then,
    from LOD2 on, at that share, the cluster cards' area gain climbs CARD_AREA_GAINS from the default the same
    way. Then the bark share climbs again with the dropped branches drawn as twig cards (`twig_cover`), and the
better of the two wins. A level costs six to twelve builds, not one per pair. Budgets LOD0's own proportion cannot meet raise
    LodBudgetError as `build_lod` does; other shares that cannot be met are skipped."""
    lods = TreeLods(skeleton, lod0)
    lod0_share = lod0.bark.n_faces / max(lod0.n_faces, 1)
    points = framing_points(lod0)
    full_share = BARK_SHARE_SCALES.index(1.0)
    default_gain = CARD_AREA_GAINS.index(CLUSTER_AREA_GAIN)
    start = BARK_SHARE_SCALES.index(_FIRST_SCALE)
    levels = []
    for level, (budget, px) in enumerate(zip(budgets, switch_px), 1):
        px = int(px)
        cameras = [switch_camera(points, azimuth, px) for azimuth in CALIBRATION_AZIMUTHS]
        references = [closed_silhouette(renderer.coverage(lod0_cover, camera)) for camera in cameras]
        tried: dict[tuple[int, int, bool], tuple[float, object]] = {}

        def score(share: int, gain: int, twigs: bool = False) -> float:
            if (share, gain, twigs) not in tried:
                scale = BARK_SHARE_SCALES[share]
                try:
                    bark_share = None if share == full_share else min(scale * lod0_share, 1.0)
                    lod = lods.build(level, budget, px, bark_share=bark_share, card_area_gain=CARD_AREA_GAINS[gain],
                                     twigs=twigs)
                except LodBudgetError:
                    if share == full_share and not twigs:
                        raise  # LOD0's own proportion is the reference: its failure is the budget's
                    tried[share, gain, twigs] = (-1.0, None)
                    return -1.0
                cover = level_cover(lod, lod0_cover, leaf_fraction, card_fraction)
                tried[share, gain, twigs] = (min(silhouette_iou(reference, closed_silhouette(renderer.coverage(cover, camera)))
                                                 for reference, camera in zip(references, cameras)), lod)
            return tried[share, gain, twigs][0]

        share = _climb(lambda index: score(index, default_gain), start, len(BARK_SHARE_SCALES))
        if tried[share, default_gain, False][1] is None:  # nothing but LOD0's proportion could be built
            score(full_share, default_gain)
            share = full_share
        gain = default_gain
        if level >= _FIRST_GAIN_LEVEL:
            gain = _climb(lambda index: score(share, index), default_gain, len(CARD_AREA_GAINS))
        twig_share = _climb(lambda index: score(index, default_gain, True), share, len(BARK_SHARE_SCALES))
        best = (share, gain, False)
        if score(twig_share, default_gain, True) > score(*best):
            best = (twig_share, default_gain, True)
        levels.append(tried[best][1])
        start = best[0]
    return levels


def level_cover(lod, lod0_cover: TreeMesh, leaf_fraction: float, card_fraction: float) -> TreeMesh:
    """What a level shows, for opaque coverage passes: its tubes and leaf cards cut to their tiles' opaque share
    (`coverage_tree`), and its twig cards as LOD0's coverage faces pressed onto each card (an exact card texture,
    before it is sampled into the atlas)."""
    cover = coverage_tree(lod.mesh, leaf_fraction, card_fraction)
    if lod.twigs is None:
        return cover
    flat = lod.twigs.flattened(lod0_cover)
    return TreeMesh(bark=MeshPart.concatenate([cover.bark, flat.bark]),
                    leaves=MeshPart.concatenate([cover.leaves, flat.leaves]), bark_color=cover.bark_color,
                    leaf_color=cover.leaf_color, name=cover.name)


def _climb(score, start: int, count: int) -> int:
    """The index in [0, count) reached from `start` by moving to the better-scoring neighbour while one scores
    higher (strictly: ties stay)."""
    best = start
    while True:
        better = [i for i in (best - 1, best + 1) if 0 <= i < count and score(i) > score(best)]
        if not better:
            return best
        best = max(better, key=score)
