"""An upper estimate of a Weber-Penn tree's size, read from its parameters alone, so a dictionary that would
exhaust a farm worker's memory is refused before anything grows.

In: `WeberPennParams`. Out: `SizeEstimate` (stems, nodes and leaves per level); `check_tree_size` raises
TreeTooLargeError naming the parameters that drive a count over its limit.

Each level's bound follows the growth code: a stem's child count is `branches` times its relative length
(0.1 + 0.9 x length over the level's longest possible length, bounded with the largest shape ratio and lengthV),
spread over the family's splines (each covering part of the family, one more for the rounding), and every
spline tip starts one more stem; first-level stems in Sapling's rotate and random modes take one per height. Splits multiply a level's splines by (1 + p) per segment, p being the
largest split probability (segSplits x 1.33, or squared after a split; splitBias on the trunk; all or nothing
against a fixed rSplits2), plus baseSplits at the trunk's first segment. The split term is the expectation over
the split draws plus three standard deviations, not a worst case (which would double every segment).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TreeTooLargeError
from .params import WeberPennParams
from .shapes import shape_ratio

__all__ = ["SizeEstimate", "estimate_size", "check_tree_size", "MAX_ESTIMATED_STEMS_PER_LEVEL",
           "MAX_ESTIMATED_NODES", "MAX_ESTIMATED_LEAVES"]

MAX_ESTIMATED_STEMS_PER_LEVEL = 1_000_000  # ten times the in-growth limit: the estimate is an upper one
MAX_ESTIMATED_NODES = 10_000_000           # dense (stems, curveRes + 1) grids of all levels together
MAX_ESTIMATED_LEAVES = 2_000_000           # one 4x4 transform per leaf, then a card each in the mesh

_SHAPE_SAMPLES = np.linspace(0.0, 1.0, 1001)


@dataclass(frozen=True)
class SizeEstimate:
    """Upper estimates per stem level (index = branch order, `levels` entries)."""

    stems: tuple[float, ...]    # stems sprouted at each level (the trunk: 1)
    splines: tuple[float, ...]  # splines after the level's splits
    nodes: tuple[float, ...]    # grid points: splines x (curveRes + 1)
    leaves: float               # leaf cards on the last level
    split_factors: tuple[float, ...]     # splines over stems at each level
    children_per_stem: tuple[float, ...]  # children one stem of each level spreads over its family

    @property
    def total_nodes(self) -> float:
        return float(sum(self.nodes))


def estimate_size(params: WeberPennParams) -> SizeEstimate:
    """Upper estimates of the stems, splines, nodes and leaves `params` grows (see the module docstring)."""
    length_ratios = _length_ratios(params)
    stems, splines, nodes, split_factors, children = [], [], [], [], []
    count, base_size, leaves = 1.0, params.base_size, 0.0
    for order in range(params.levels):
        last = order == params.levels - 1
        if order > 0:
            base_size *= params.base_size_shrink
        if last:
            base_size = 0.0
        if order > 0 and params.stem_levels[order].length == 0:
            count = 0.0
        factor = _split_factor(params, order, length_ratios[order])
        level_splines = count * factor
        if factor > 1:  # the splits are random draws: three standard deviations above their expectation
            level_splines += 3 * np.sqrt(level_splines)
        sprouts = _sprouts_per_stem(params, order, length_ratios[order], base_size)
        stems.append(count)
        splines.append(level_splines)
        nodes.append(level_splines * (params.stem_levels[order].curve_res + 1))
        split_factors.append(factor)
        children.append(sprouts)
        points = _sprout_points(params, order, count, level_splines, sprouts)
        if last and params.leaves.count:
            leaves = level_splines * -params.leaves.count if params.leaves.count < 0 else points
        count = points
    return SizeEstimate(tuple(stems), tuple(splines), tuple(nodes), leaves, tuple(split_factors), tuple(children))


def check_tree_size(params: WeberPennParams) -> SizeEstimate:
    """The estimate of `params`; TreeTooLargeError where a level's stems, all nodes or the leaves exceed their
    limit, naming the parameters that multiply up to it."""
    estimate = estimate_size(params)
    for order, count in enumerate(estimate.splines):
        if count > MAX_ESTIMATED_STEMS_PER_LEVEL:
            raise TreeTooLargeError(
                f"level {order} would grow about {count:,.0f} stems (limit {MAX_ESTIMATED_STEMS_PER_LEVEL:,} per "
                f"level): {_drivers(params, estimate, order)}; lower them")
    if estimate.total_nodes > MAX_ESTIMATED_NODES:
        raise TreeTooLargeError(
            f"the tree would grow about {estimate.total_nodes:,.0f} stem nodes (limit {MAX_ESTIMATED_NODES:,}): "
            f"{_drivers(params, estimate, params.levels - 1)}; lower them")
    if estimate.leaves > MAX_ESTIMATED_LEAVES:
        raise TreeTooLargeError(
            f"the tree would grow about {estimate.leaves:,.0f} leaves (limit {MAX_ESTIMATED_LEAVES:,}): "
            f"leaves = {params.leaves.count} per last-level stem, on "
            f"{_drivers(params, estimate, params.levels - 1)}; lower them")
    return estimate


def _length_ratios(params: WeberPennParams) -> list[float]:
    """Per level, an upper bound of a stem's length over the level's longest length (tree scale times the
    product of `length` up to the level): the largest shape ratio and (1 + lengthV) of every level below."""
    ratios, ratio = [1.0], 1.0
    for order in range(1, 4):
        shape = (shape_ratio(params.shape, _SHAPE_SAMPLES, params.custom_shape) if order == 1
                 else shape_ratio(params.side_shape, _SHAPE_SAMPLES))
        ratio *= (1 + params.stem_levels[order - 1].length_variation) * max(float(np.max(np.abs(shape))), 0.0)
        ratios.append(ratio)
    return ratios


def _split_factor(params: WeberPennParams, order: int, length_ratio: float) -> float:
    """Expected splines per stem after the level's splits, every split at its largest probability: splines that
    did not split at the last step split with segSplits x 1.33, those that did (and new split-offs) with its
    square."""
    stem = params.stem_levels[order]
    n_segments = stem.curve_res
    seg_splits = stem.seg_splits
    if order == 0:
        seg_splits *= 1 + abs(params.split_bias)
    length_factor = 1.0
    if order >= 1 and params.split_by_length:
        length_factor = length_ratio * (1 + stem.length_variation)
    after_rest = _split_probability(params, 1.33 * seg_splits * length_factor)
    after_split = _split_probability(params, seg_splits * seg_splits * length_factor)
    resting, just_split = 1.0, 0.0
    for step in range(1, n_segments):
        if order == 0 and step == 1:
            resting, just_split = resting + just_split, (resting + just_split) * params.base_splits
            continue
        if order == 0 and step < (n_segments - 1) * params.split_height:
            resting, just_split = resting + just_split, 0.0
            continue
        if order == 0 and step == int((n_segments - 1) * params.split_height) + 1 and seg_splits > 0:
            resting, just_split = 0.0, 2 * (resting + just_split)  # the trunk's first split is forced
            continue
        resting, just_split = (resting * (1 - after_rest) + just_split * (1 - after_split),
                               2 * (resting * after_rest + just_split * after_split))
    return resting + just_split


def _split_probability(params: WeberPennParams, probability: float) -> float:
    """The chance a spline splits at a step: `probability` against a uniform draw, or against a fixed rSplits2."""
    threshold = params.draws.split_threshold
    return min(probability, 1.0) if threshold is None else float(threshold < probability)


def _sprouts_per_stem(params: WeberPennParams, order: int, length_ratio: float, base_size: float) -> float:
    """Most children (next-level stems or leaves) one stem of level `order` spreads over its family."""
    relative_length = 0.1 + 0.9 * length_ratio
    if params.levels == 1:
        children = float(params.leaves.count)
    elif order == 0:
        children = float(params.stem_levels[1].branches)
    elif order == params.levels - 1:
        leaves = params.leaves
        spread = float(np.max(shape_ratio(leaves.distribution, _SHAPE_SAMPLES)))
        children = leaves.count * relative_length * spread
    else:
        children = params.stem_levels[order + 1].branches * relative_length
    if children <= 0:
        return 0.0
    if order == 0 and params.rotate_mode != "original":  # one sprout per height, above the base size
        count = np.floor(children)
        return float(count - max(np.floor(min(max(base_size, 0.0), 0.999) * (count + 1)), 0.0))
    return children


def _sprout_points(params: WeberPennParams, order: int, stems: float, splines: float, sprouts: float) -> float:
    """Most child points of a level of `stems` families grown into `splines`: each family's sprouts over the
    splines that cover them (more where lengthV makes splits longer than their family's stem, plus one for the
    rounding on each spline), and every spline's tip."""
    if order == 0 and params.rotate_mode != "original":
        along = sprouts * (splines if order == params.levels - 1 else 1.0)  # first-level stems: one per height
    else:
        variation = params.stem_levels[order].length_variation
        spread = (1 + variation) / max(1 - variation, 1e-3)
        along = min(splines * (np.floor(sprouts + 0.5) + 1), spread * (stems * sprouts + splines) + splines)
    return along + splines


def _drivers(params: WeberPennParams, estimate: SizeEstimate, order: int) -> str:
    """The parameters that multiply up to level `order`'s count, e.g. 'branches[1] = 2000 x branches[2] = 2000'."""
    terms = []
    for level in range(order + 1):
        stem = params.stem_levels[level]
        factor = estimate.split_factors[level]
        if factor > 1.5:
            splits = f"segSplits[{level}] = {stem.seg_splits} over curveRes[{level}] = {stem.curve_res}"
            if level == 0 and params.base_splits:
                splits += f" and baseSplits = {params.base_splits}"
            terms.append(f"{splits} (x{factor:,.0f} splits)")
        if level < order:
            sprouts = estimate.children_per_stem[level]
            key = f"branches[{level + 1}] = {params.stem_levels[level + 1].branches}"
            if params.levels == 1:
                key = f"leaves = {params.leaves.count}"
            terms.append(f"{key} (x{sprouts + 1:,.0f} per stem)")
    return " x ".join(terms) if terms else f"curveRes[{order}] = {params.stem_levels[order].curve_res}"
