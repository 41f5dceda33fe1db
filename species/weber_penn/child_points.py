"""Where the next Weber-Penn level (or the leaves) sprouts along a grown level: Sapling's findChildPoints and
interpStem, vectorized over stems.

In: a grown `Level` and the parameters. Out: `ChildPoints`, arrays over the P sprouting points.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from ..geometry.vectors import unit_vectors
from .params import WeberPennParams
from .stems import Level

__all__ = ["ChildPoints", "child_points"]


@dataclass
class ChildPoints:
    """Where the stems of the next level (or the leaves) sprout, arrays over P points."""

    position: np.ndarray             # (P, 3) metres
    tangent: np.ndarray              # (P, 3) unit direction of the parent stem there
    parent_start_radius: np.ndarray  # (P,) metres, start radius of the parent stem
    parent_radius: np.ndarray        # (P,) metres, parent radius at the point
    offset: np.ndarray               # (P,) t along the parent family (1 = a stem tip)
    stem_offset: np.ndarray          # (P,) offset rescaled above the base size
    parent_length: np.ndarray        # (P,) metres, length of the parent stem
    spline: np.ndarray               # (P,) int, parent spline id
    u: np.ndarray                    # (P,) position on the parent spline in segment steps

    def take(self, index: np.ndarray) -> ChildPoints:
        return ChildPoints(*(getattr(self, f.name)[index] for f in fields(self)))

    def __len__(self) -> int:
        return len(self.offset)


def child_points(level: Level, params: WeberPennParams, order: int, *, base_size: float,
                 rng: np.random.Generator) -> ChildPoints:
    """Points along each stem family of `level` (branch order `order`) where the next level sprouts, then every
    spline's tip; none below `base_size` (a fraction of the family's length)."""
    count, spacing = _sprout_counts(level, params, order)
    family_of_t, t, index = _family_offsets(count, spacing, base_size=base_size)
    if order == 0 and params.rings > 0:
        family_of_t, t = _in_whorls(family_of_t, t, index, count, params.rings, base_size=base_size, rng=rng)
    if order == 0:
        t = _distributed_up_the_trunk(t, params.branch_distribution, base_size)
    spline, t, bottom, top = _on_splines(level, family_of_t, t)
    along = _interpolated(level, spline, t, bottom, top, base_size=base_size)
    return _with_tips(level, along)


def _sprout_counts(level: Level, params: WeberPennParams, order: int) -> tuple[np.ndarray, np.ndarray]:
    """(F,) int sprouts per family and (F,) their spacing's denominator (t = (a + 1) / spacing)."""
    n_families = int(level.family.max()) + 1
    children = level.children_of_family
    segments = np.bincount(level.family, weights=level.n_points - 1, minlength=n_families)
    if order == 0 and params.rotate_mode != "original":
        count = np.floor(children).astype(np.int64)
        spacing = children
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            per_segment = np.where(segments > 0, children / segments, 0.0)
        spacing = np.round(per_segment * level.n_segments)
        count = spacing.astype(np.int64)
    none = children <= 0
    return np.where(none, 1, count), np.where(none, 1.0, spacing)


def _family_offsets(count: np.ndarray, spacing: np.ndarray, *,
                    base_size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat list of (family, t, a) with t = (a + 1) / spacing for a < count, the lowest base_size share
    trimmed."""
    n_families = len(count)
    family_of_t = np.repeat(np.arange(n_families), count)
    index = np.arange(len(family_of_t)) - np.repeat(np.cumsum(count) - count, count)
    t = (index + 1) / spacing[family_of_t]
    trim = np.floor(base_size * (count + 1)).astype(np.int64)
    keep = index >= trim[family_of_t]
    return family_of_t[keep], t[keep], index[keep]


def _in_whorls(family_of_t: np.ndarray, t: np.ndarray, index: np.ndarray, count: np.ndarray, rings: int, *,
               base_size: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Sapling's nrings: trunk sprouts snapped to `rings` heights (jittered), the last one kept at the tip."""
    not_last = index < (count - 1)[family_of_t]
    jitter = rng.uniform(0.995, 1.005, len(t))
    t = np.where(not_last, np.floor(t * rings) / rings * jitter, 1.0)
    keep = t > base_size
    return family_of_t[keep], t[keep]


def _distributed_up_the_trunk(t: np.ndarray, branch_distribution: float, base_size: float) -> np.ndarray:
    """branchDist: above the base size, t bunched toward the top (< 1) or the base (> 1)."""
    x = (t - base_size) / (1 - base_size)
    if branch_distribution < 1.0:
        x = np.power(np.clip(x, 0, None), 1 / branch_distribution)
    else:
        x = 1 - np.power(np.clip(1 - x, 0, None), branch_distribution)
    return x * (1 - base_size) + base_size


def _on_splines(level: Level, family_of_t: np.ndarray, t: np.ndarray):
    """Pair every spline with its family's t values and keep those inside the spline's stretch of the family.

    Returns (spline row (Q,) int, t (Q,), bottom (S,), top (S,)): each spline's stretch as t of its family.
    """
    family = level.family
    n_families = int(family.max()) + 1
    length = (level.n_points - 1) * level.segment_length
    family_length = np.zeros(n_families)
    np.maximum.at(family_length, family, level.offset_length + length)
    bottom = level.offset_length / family_length[family]
    top = bottom + length / family_length[family]
    by_family = np.argsort(family_of_t, kind="stable")
    family_of_t, t = family_of_t[by_family], t[by_family]
    t_count = np.bincount(family_of_t, minlength=n_families)
    t_start = np.cumsum(t_count) - t_count
    repeats = t_count[family]
    spline = np.repeat(np.arange(len(family)), repeats)
    within = np.arange(repeats.sum()) - np.repeat(np.cumsum(repeats) - repeats, repeats)
    t = t[np.repeat(t_start[family], repeats) + within]
    inside = (t >= bottom[spline]) & (t <= top[spline]) & (t < 1.0)
    return spline[inside], t[inside], bottom, top


def _interpolated(level: Level, spline: np.ndarray, t: np.ndarray, bottom: np.ndarray, top: np.ndarray, *,
                  base_size: float) -> dict:
    """Position, tangent and radius at t on each spline row, as ChildPoints fields (tips not included)."""
    scaled = (t - bottom[spline]) / np.maximum(top[spline] - bottom[spline], 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        stem_offset = (t - base_size) / (top[spline] - base_size) * (1 - base_size) + base_size
    segments = level.n_points[spline] - 1
    at = segments * scaled
    index = np.minimum(np.floor(at).astype(np.int64), segments - 1)
    fraction = at - index
    step = level.first_step[spline] + index
    below, above = level.points[spline, step], level.points[spline, step + 1]
    radius = level.radii[spline, step] * (1 - fraction) + level.radii[spline, step + 1] * fraction
    return {"position": below + fraction[:, None] * (above - below), "tangent": unit_vectors(above - below),
            "parent_start_radius": level.start_radius[spline], "parent_radius": radius, "offset": t,
            "stem_offset": stem_offset, "parent_length": (level.n_segments * level.segment_length)[spline],
            "spline": level.spline_id[spline], "u": step + fraction}


def _with_tips(level: Level, along: dict) -> ChildPoints:
    """The points along the splines followed by every spline's tip."""
    rows = np.arange(level.n_splines)
    last_step = level.first_step + level.n_points - 1
    tips = {"position": level.points[rows, last_step],
            "tangent": unit_vectors(level.points[rows, last_step] - level.points[rows, last_step - 1]),
            "parent_start_radius": level.start_radius, "parent_radius": level.radii[rows, last_step],
            "offset": np.ones(len(rows)), "stem_offset": np.ones(len(rows)),
            "parent_length": level.n_segments * level.segment_length, "spline": level.spline_id,
            "u": last_step.astype(np.float64)}
    return ChildPoints(**{name: np.concatenate([along[name], tips[name]]) for name in tips})
