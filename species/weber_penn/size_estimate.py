"""An upper estimate of a Weber-Penn tree's size, read from its parameters alone, so a dictionary that would
exhaust a farm worker's memory is refused before anything grows.

In: `WeberPennParams`. Out: `SizeEstimate` (stems, nodes and leaves per level); `check_tree_size` raises
TreeTooLargeError naming the parameters that drive a count over its limit.

The estimate follows the growth code level by level, with the stems of a level grouped in classes by relative
length (length over the level's longest possible one), since a stem's length sets its split chance (splitByLen)
and its child count. Per class, the splits are a two-type branching process over the curve segments (a spline
that did not split at the last step splits with segSplits x 1.33, one that did with segSplits squared; baseSplits
and the forced first split on the trunk), whose mean and variance are exact. A family's children are its
`children` spread over its splines (each child point sits on every spline covering it, one spacing for the whole
family), plus one per spline tip; first-level stems in Sapling's rotate and random modes take one per height.
Children take their length from the crown shape at their place on the parent. Counts are the expectation plus
three standard deviations, the variance carried down the levels as a branching process's is.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import TreeTooLargeError
from .child_points import _distributed_up_the_trunk, _family_offsets
from .params import WeberPennParams
from .shapes import shape_ratio
from .stems import MAX_STEMS_PER_LEVEL

__all__ = ["SizeEstimate", "estimate_size", "check_tree_size", "MAX_ESTIMATED_STEMS_PER_LEVEL",
           "MAX_ESTIMATED_NODES", "MAX_ESTIMATED_LEAVES"]

# The estimate is 1-2x the real count: a level estimated above twice the in-growth limit would be stopped there
# anyway, after its memory was spent.
MAX_ESTIMATED_STEMS_PER_LEVEL = 2 * MAX_STEMS_PER_LEVEL
MAX_ESTIMATED_NODES = 10_000_000           # dense (stems, curveRes + 1) grids of all levels together
MAX_ESTIMATED_LEAVES = 2_000_000           # one 4x4 transform per leaf, then a card each in the mesh

_STANDARD_DEVIATIONS = 3.0  # the margin above the expected count
_LENGTH_CLASSES = 64        # classes of relative length per level
_LENGTH_FACTORS = (np.arange(9) + 0.5) / 9  # quadrature of lengthV's uniform factor, as fractions of its range
_MIN_LENGTH = 1e-5          # stems no longer than this share of the tree scale are dropped, as in growth


@dataclass(frozen=True)
class SizeEstimate:
    """Upper estimates per stem level (index = branch order, `levels` entries)."""

    stems: tuple[float, ...]    # stems sprouted at each level (the trunk: 1)
    splines: tuple[float, ...]  # splines after the level's splits
    nodes: tuple[float, ...]    # grid points: splines x (curveRes + 1)
    leaves: float               # leaf cards
    split_factors: tuple[float, ...]     # expected splines over stems at each level
    children_per_stem: tuple[float, ...]  # expected children one stem of each level spreads over its family

    @property
    def total_nodes(self) -> float:
        return float(sum(self.nodes))


@dataclass(frozen=True)
class _Families:
    """The stem families of one level in classes of relative length, C classes."""

    count: np.ndarray            # (C,) expected families in each class
    covariance: np.ndarray       # (C, C) covariance of those counts
    relative_length: np.ndarray  # (C,) stem length over tree scale x the product of `length` up to the level
    children: np.ndarray         # (C,) stems (or leaves) each family sprouts, as Level.children

    def upper(self, per_family: np.ndarray, variance: np.ndarray | None = None) -> float:
        """Expectation plus the margin of a sum over families of `per_family` (C,) each, `variance` (C,) each."""
        mean = float(per_family @ self.count)
        spread = float(per_family @ self.covariance @ per_family)
        if variance is not None:
            spread += float(variance @ self.count)
        value = mean + _STANDARD_DEVIATIONS * np.sqrt(max(spread, 0.0))
        return value if np.isfinite(value) else np.inf  # past float range: over every limit


@dataclass(frozen=True)
class _Splits:
    """What one family of each class grows into through its splits, C classes over K segments."""

    mean: np.ndarray      # (C,) expected splines
    variance: np.ndarray  # (C,) their variance
    alive: np.ndarray     # (C, K) expected splines growing each segment


def estimate_size(params: WeberPennParams) -> SizeEstimate:
    """Upper estimates of the stems, splines, nodes and leaves `params` grows (see the module docstring)."""
    families = _trunk(params)
    stems, splines, nodes, split_factors, children = [], [], [], [], []
    base_size, leaves = params.base_size, 0.0
    for order in range(params.levels):
        last = order == params.levels - 1
        if order > 0:
            base_size *= params.base_size_shrink
        if last:
            base_size = 0.0
        splits = _splits(params, order, families)
        expected = max(float(families.count.sum()), 1e-12)
        stems.append(families.upper(np.ones(len(families.count))))
        splines.append(families.upper(splits.mean, splits.variance))
        nodes.append(splines[-1] * (params.stem_levels[order].curve_res + 1))
        split_factors.append(float(splits.mean @ families.count) / expected)
        children.append(float(families.children @ families.count) / expected)
        if not last:
            grown = _offspring(params, order, families, splits, base_size)
        if last or not grown.count.any():  # the leaves hang on the last level that grew
            if params.leaves.count:
                parent, _, along = _along(params, order, families, splits, base_size)
                points = np.bincount(parent, weights=along, minlength=len(families.count)) + splits.mean
                variance = splits.variance
                if order == 0 and params.rotate_mode != "original":  # one spacing whatever the splits
                    variance = variance * (points / splits.mean) ** 2
                leaves = families.upper(points, variance) * max(-params.leaves.count, 1)
            break
        families = grown
    missing = params.levels - len(stems)
    return SizeEstimate(tuple(stems) + (0.0,) * missing, tuple(splines) + (0.0,) * missing,
                        tuple(nodes) + (0.0,) * missing, leaves, tuple(split_factors) + (0.0,) * missing,
                        tuple(children) + (0.0,) * missing)


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


def _trunk(params: WeberPennParams) -> _Families:
    """One trunk, as long as its level allows; it sprouts branches[1] stems (the leaves on a one-level tree)."""
    children = params.leaves.count if params.levels == 1 else params.stem_levels[1].branches
    return _Families(count=np.ones(1), covariance=np.zeros((1, 1)), relative_length=np.ones(1),
                     children=np.array([float(max(children, 0))]))


# ---------------------------------------------------------------------------------------------- splits
def _splits(params: WeberPennParams, order: int, families: _Families) -> _Splits:
    """Mean and variance of the splines one family of each class grows into: at each step a spline that rested
    at the step before, or one that split, splits with its chance into itself and its split-offs, all of which
    have then just split (a two-type branching process)."""
    n_segments = params.stem_levels[order].curve_res
    n_classes = len(families.count)
    mean = np.zeros((n_classes, 2))  # splines that rested / just split at the step before
    mean[:, 0] = 1.0
    covariance = np.zeros((n_classes, 2, 2))
    alive = np.ones((n_classes, n_segments))
    for step in range(1, n_segments):
        chance, split_offs = _split_chances(params, order, step, families.relative_length)
        change = np.array([-1.0, 1.0 + split_offs])  # what one split does to (rested, just split)
        offspring = np.array([1.0, 0.0]) + chance[:, :, None] * change  # (C, 2 kinds before, 2 kinds after)
        drawn = (mean * chance * (1 - chance)).sum(axis=1)
        covariance = (np.einsum("cij,cik,ckl->cjl", offspring, covariance, offspring)
                      + drawn[:, None, None] * np.outer(change, change))
        mean = np.einsum("ci,cij->cj", mean, offspring)
        alive[:, step] = mean.sum(axis=1)
    return _Splits(mean=mean.sum(axis=1), variance=covariance.sum(axis=(1, 2)), alive=alive)


def _split_chances(params: WeberPennParams, order: int, step: int,
                   relative_length: np.ndarray) -> tuple[np.ndarray, int]:
    """(C, 2) chance that a spline which rested / split at the step before splits at `step`, and the stems
    each split adds (the growth code's _split_counts): baseSplits at the trunk's first step, none below its
    split height, its first split forced; else segSplits x 1.33 after a rest and squared after a split, on
    branches times the spline's relative length (splitByLen)."""
    stem = params.stem_levels[order]
    n_segments = stem.curve_res
    sure = np.ones((len(relative_length), 2))
    if order == 0 and step == 1:
        return sure * (params.base_splits > 0), max(params.base_splits, 1)
    if order == 0 and step < (n_segments - 1) * params.split_height:
        return sure * 0.0, 1
    progress = step / (n_segments - 1) if n_segments > 1 else 1.0
    seg_splits = stem.seg_splits
    if order == 0:
        seg_splits = max(((2 * params.split_bias) * (progress - 0.5) + 1) * seg_splits, 0.0)
        if step == int((n_segments - 1) * params.split_height) + 1 and seg_splits > 0:
            return sure, 1
    length = np.ones((len(relative_length), 1))
    if order >= 1 and params.split_by_length:  # the spline's length after its own lengthV factor
        variation = stem.length_variation
        length = relative_length[:, None] * (1 - variation + 2 * variation * _LENGTH_FACTORS)
    return np.stack([_split_chance(params, 1.33 * seg_splits * length),
                     _split_chance(params, seg_splits ** 2 * length)], axis=1), 1


def _split_chance(params: WeberPennParams, probability: np.ndarray) -> np.ndarray:
    """(C,) mean over the length factors (C, Q) of the chance a spline splits: `probability` against a uniform
    draw, or against a fixed rSplits2."""
    threshold = params.draws.split_threshold
    hit = np.minimum(probability, 1.0) if threshold is None else (threshold < probability).astype(np.float64)
    return hit.mean(axis=1)


# ---------------------------------------------------------------------------------------------- children
def _along(params: WeberPennParams, order: int, families: _Families, splits: _Splits,
           base_size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P,) parent class, (P,) offset t on the family and (P,) expected child points there per family: the
    family's sprouts at t = (a + 1) / spacing above the base size and below the tip, one on every spline that
    grows the segment holding t (tips not included)."""
    if order == 0 and params.rotate_mode != "original":
        parent, offset = _trunk_offsets(params, families, base_size)
        share = np.ones(len(parent))
    else:
        parent, offset, share = _spaced_offsets(families, splits, base_size)
        if order == 0:
            offset = _distributed_up_the_trunk(offset, params.branch_distribution, base_size)
    n_segments = splits.alive.shape[1]
    segment = np.minimum(np.floor(offset * n_segments).astype(np.int64), n_segments - 1)
    return parent, offset, share * splits.alive[parent, segment]


def _spaced_offsets(families: _Families, splits: _Splits,
                    base_size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P,) class, (P,) t and (P,) share of the sprouts of a family with spacing round(children x curveRes /
    the family's segments): a class's families round their own spacings, at most half a step up, so the class
    takes its mean spacing plus a half, shared between the two whole spacings around it."""
    n_classes, n_segments = splits.alive.shape
    spacing = np.where(families.children > 0,
                       families.children * n_segments / splits.alive.sum(axis=1) + 0.5, 0.0)
    low = np.floor(spacing)
    high_share = spacing - low
    spacing = np.concatenate([low, low + 1]).astype(np.int64)
    share = np.concatenate([1 - high_share, high_share])
    count = np.where(share > 0, spacing, 0)
    family, t, _ = _family_offsets(count, np.maximum(spacing, 1).astype(np.float64), base_size=base_size)
    below_tip = t < 1.0
    family = family[below_tip]
    return family % n_classes, t[below_tip], share[family]


def _trunk_offsets(params: WeberPennParams, families: _Families, base_size: float) -> tuple[np.ndarray, np.ndarray]:
    """(P,) class and (P,) t of the trunk's sprouts in Sapling's rotate and random modes: floor(children) heights
    spaced 1 / children apart, in whorls where nrings is set, bunched by branchDist."""
    children = families.children
    count = np.floor(children).astype(np.int64)
    family, offset, index = _family_offsets(np.where(children > 0, count, 0), np.maximum(children, 1e-12),
                                            base_size=base_size)
    if params.rings > 0:  # snapped to `rings` heights, the last one at the tip (growth jitters them apart)
        offset = np.where(index < (count - 1)[family], np.floor(offset * params.rings) / params.rings, 1.0)
        family, offset = family[offset > base_size], offset[offset > base_size]
    offset = _distributed_up_the_trunk(offset, params.branch_distribution, base_size)
    below_tip = offset < 1.0
    return family[below_tip], offset[below_tip]


def _offspring(params: WeberPennParams, order: int, families: _Families, splits: _Splits,
               base_size: float) -> _Families:
    """The stem families of level `order + 1`, sprouted along and at the tips of level `order`'s splines."""
    n_classes = len(families.count)
    parent, offset, weight = _along(params, order, families, splits, base_size)
    if order == 0 and params.rotate_mode != "original":  # one first-level stem per height
        weight = np.ones(len(parent))
    parent = np.concatenate([parent, np.arange(n_classes)])
    offset = np.concatenate([offset, np.ones(n_classes)])
    weight = np.concatenate([weight, splits.mean])
    ratio = (1 - offset) / (1 - min(0.999, base_size))
    shape = (shape_ratio(params.shape, ratio, params.custom_shape) if order == 0
             else shape_ratio(params.side_shape, ratio))
    # A spline holds children in proportion to its length, so those along it sit on splines lengthV made
    # longer: E[f^2] / E[f] = 1 + v^2 / 3 for a factor f uniform in 1 +- v.
    along_bias = np.where(offset < 1, 1 + params.stem_levels[order].length_variation ** 2 / 3, 1.0)
    relative_length = families.relative_length[parent] * shape * along_bias
    child = order + 1
    kept = relative_length * float(np.prod(params.stem_lengths()[: child + 1])) > _MIN_LENGTH
    if child == params.levels - 1:
        leaves = params.leaves
        children = (np.zeros(len(parent)) if leaves.count < 0 else
                    leaves.count * (0.1 + 0.9 * relative_length) * shape_ratio(leaves.distribution, 1 - offset))
    else:
        children = params.stem_levels[min(3, child + 1)].branches * (0.1 + 0.9 * relative_length)
    at_tip = np.zeros(len(parent), bool)
    at_tip[-n_classes:] = True
    return _classes(families, splits, parent, relative_length, children, weight * kept, at_tip & kept)


def _classes(families: _Families, splits: _Splits, parent: np.ndarray, relative_length: np.ndarray,
             children: np.ndarray, weight: np.ndarray, at_tip: np.ndarray) -> _Families:
    """Child stems (P,) of parent classes `parent`, `weight` of them per parent family, grouped in classes of
    relative length; tip counts carry their parents' split variance."""
    top = float(relative_length[weight > 0].max()) if (weight > 0).any() else 1.0
    grouped = np.minimum((relative_length / max(top, 1e-12) * _LENGTH_CLASSES).astype(np.int64),
                         _LENGTH_CLASSES - 1)
    n_classes = len(families.count)
    offspring = np.zeros((n_classes, _LENGTH_CLASSES))
    np.add.at(offspring, (parent, grouped), weight)
    tips = np.zeros((n_classes, _LENGTH_CLASSES))
    np.add.at(tips, (parent[at_tip], grouped[at_tip]), 1.0)
    expected = weight * families.count[parent]
    count = offspring.T @ families.count
    total = np.maximum(np.bincount(grouped, weights=expected, minlength=_LENGTH_CLASSES), 1e-300)
    mean_length = np.bincount(grouped, weights=expected * relative_length, minlength=_LENGTH_CLASSES) / total
    mean_children = np.bincount(grouped, weights=expected * children, minlength=_LENGTH_CLASSES) / total
    covariance = (offspring.T @ families.covariance @ offspring
                  + tips.T @ (tips * (families.count * splits.variance)[:, None]))
    used = count > 0
    return _Families(count=count[used], covariance=covariance[np.ix_(used, used)],
                     relative_length=mean_length[used], children=mean_children[used])


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
