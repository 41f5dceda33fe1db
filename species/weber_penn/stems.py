"""Growing one level of Weber-Penn stems in lockstep: curvature, splits, vertical attraction, envelope pruning.

`grow_level(stems, params, order, ...)` takes the new stems of a level (`Level.new_stems`) and returns them grown,
with the split-off stems appended; points live in dense (S, curveRes + 1) grids indexed by growth step.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ..errors import TreeTooLargeError
from ..geometry import rotations as rot
from ..geometry.vectors import unit_vectors
from .params import StemLevelParams, WeberPennParams
from .shapes import shape_ratio
from .stem_directions import (bent_direction, branch_turn, crown_taper, sapling_split_angles, segment_frames,
                              split_angle, spread_angle, world_directions)

__all__ = ["Level", "grow_level", "MAX_STEMS_PER_LEVEL"]

TAU = 2 * np.pi
MAX_STEMS_PER_LEVEL = 100_000  # beyond this a tree no longer fits a farm worker's memory or a GLB reader


@dataclass
class Level:
    """The stems (splines) of one level, arrays over S splines; a split appends a row.

    A spline's points are indexed by growth step, 0..n_segments; a split's own points start at `first_step`.
    """

    n_segments: int                # the level's curveRes: growth steps of every spline
    segment_length: np.ndarray     # (S,) metres per segment
    curvature: np.ndarray          # (S,) radians of bend per segment
    start_radius: np.ndarray       # (S,) metres, radius at the stem start
    end_radius: np.ndarray         # (S,) metres, radius at the stem end
    children: np.ndarray           # (S,) child stems (or leaves) this stem's family sprouts
    family: np.ndarray             # (S,) int, the original stem a split descends from
    first_step: np.ndarray         # (S,) int, growth step at which the spline starts
    offset_length: np.ndarray      # (S,) metres of family stem below the spline start
    collar: np.ndarray             # (S,) bool, stem sprouted from a parent (owns a collar node)
    parent_spline: np.ndarray      # (S,) int, global id of the parent spline (-1: trunk or a split, see parent_row)
    parent_row: np.ndarray         # (S,) int, row of the spline a split came from (-1 otherwise)
    parent_u: np.ndarray           # (S,) position of the start on the parent spline, in steps
    attach_points: np.ndarray      # (S, 3) metres, where a sprouted stem leaves its parent's axis
    attach_radii: np.ndarray       # (S,) metres, parent radius there
    collar_points: np.ndarray      # (S, 3) metres, the sprouted stem's own first node, at the parent's surface
    start_direction: np.ndarray    # (S, 3) unit direction the spline starts growing in
    points: np.ndarray             # (S, K + 1, 3) metres, positions by growth step
    radii: np.ndarray              # (S, K + 1) metres
    valid: np.ndarray              # (S, K + 1) bool
    spline_id: np.ndarray          # (S,) int, global spline id (set after growth)

    @classmethod
    def new_stems(cls, *, start_points, directions, segment_length, curvature, start_radius, end_radius, children,
                  first_radius, parent_spline, parent_u, collar: bool, n_segments: int,
                  parent_radius=None) -> Level:
        """S stems starting at `start_points` (S, 3) toward `directions` (S, 3), not grown yet."""
        count = len(start_points)
        directions = unit_vectors(directions)
        points = np.zeros((count, n_segments + 1, 3))
        radii = np.zeros((count, n_segments + 1))
        valid = np.zeros((count, n_segments + 1), bool)
        points[:, 0], radii[:, 0], valid[:, 0] = start_points, first_radius, True
        parent_radius = np.zeros(count) if parent_radius is None else np.asarray(parent_radius, np.float64)
        collar_points = start_points + directions * np.minimum(parent_radius, 0.5 * segment_length)[:, None]
        return cls(
            n_segments=n_segments, segment_length=segment_length.astype(np.float64),
            curvature=curvature.astype(np.float64), start_radius=start_radius.astype(np.float64),
            end_radius=end_radius.astype(np.float64), children=children.astype(np.float64),
            family=np.arange(count), first_step=np.zeros(count, np.int64), offset_length=np.zeros(count),
            collar=np.full(count, collar), parent_spline=np.asarray(parent_spline), parent_row=np.full(count, -1),
            parent_u=np.asarray(parent_u, np.float64), attach_points=np.asarray(start_points, np.float64),
            attach_radii=parent_radius, collar_points=collar_points, start_direction=directions, points=points,
            radii=radii, valid=valid, spline_id=np.arange(count))

    @property
    def n_splines(self) -> int:
        return len(self.segment_length)

    @property
    def n_points(self) -> np.ndarray:
        return self.valid.sum(axis=1)

    @property
    def rows(self) -> dict:
        """Every per-spline array by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "n_segments"}

    @property
    def children_of_family(self) -> np.ndarray:
        out = np.zeros(int(self.family.max()) + 1)
        roots = self.family == np.arange(self.n_splines)
        out[self.family[roots]] = self.children[roots]
        return out


@dataclass
class _GrowthFront:
    """Where each spline of a growing level has got to, arrays over its S splines (the Level's rows)."""

    positions: np.ndarray              # (S, 3) metres, the last grown point
    directions: np.ndarray             # (S, 3) unit direction of the last segment
    bend_sign: np.ndarray              # (S,) +1 or -1: the curvature variation alternates every segment
    split_before: np.ndarray           # (S,) int 0 or 1, the spline split at the previous step
    last_split_turn: np.ndarray        # (S,) radians, rotation of the latest split (NaN before the first)
    family_segment_length: np.ndarray  # (S,) metres, the family's segment length before variation

    @classmethod
    def start(cls, level: Level, family_segment_length: np.ndarray) -> _GrowthFront:
        count = level.n_splines
        return cls(positions=level.points[:, 0].copy(), directions=level.start_direction.copy(),
                   bend_sign=np.ones(count), split_before=np.zeros(count, np.int64),
                   last_split_turn=np.full(count, np.nan), family_segment_length=family_segment_length.copy())

    def advance(self, positions: np.ndarray, directions: np.ndarray, splitting: np.ndarray) -> None:
        self.positions, self.directions = positions, directions
        self.split_before = splitting.astype(np.int64)

    def add(self, split_off: _SplitOff) -> None:
        """Append the splines that split off this step, as having just split."""
        count = len(split_off.directions)
        self.positions = np.concatenate([self.positions, split_off.rows["points"][:, split_off.step + 1]])
        self.directions = np.concatenate([self.directions, split_off.directions])
        self.bend_sign = np.concatenate([self.bend_sign, np.ones(count)])
        self.split_before = np.concatenate([self.split_before, np.ones(count, np.int64)])
        self.last_split_turn = np.concatenate([self.last_split_turn, split_off.last_split_turn])
        self.family_segment_length = np.concatenate([self.family_segment_length, split_off.family_segment_length])


@dataclass(frozen=True)
class _SegmentTurns:
    """One growth step's orientation of every spline, shared by its continuing stem and its split-offs."""

    step: int
    frames: np.ndarray         # (S, 3, 3) each spline's frame for the segment
    bend: np.ndarray           # (S,) radians, bend in the stem's plane
    bend_across: np.ndarray    # (S,) radians, bend across it
    split_angle: np.ndarray    # (S,) radians between a split and its stem (0 where none splits)
    turn: np.ndarray           # (S,) radians, rotation of a split around the stem (0 where none splits)
    spread: np.ndarray         # (S,) radians a branch split turns out of the splitting plane (0 where none splits)
    length_factor: np.ndarray  # (S,) factor on the segment length (the trunk's crown taper; 1 for branches)


@dataclass(frozen=True)
class _SplitOff:
    """The splines that split off at one step: their Level rows and their growth-front state."""

    step: int
    rows: dict                         # Level field name -> (C, ...) array
    directions: np.ndarray             # (C, 3) unit direction of the first segment
    last_split_turn: np.ndarray        # (C,) radians
    family_segment_length: np.ndarray  # (C,) metres


def _append(level: Level, new_rows: dict) -> Level:
    merged = {name: np.concatenate([values, new_rows[name]]) for name, values in level.rows.items()}
    return Level(n_segments=level.n_segments, **merged)


def _length_factors(stem_params: StemLevelParams, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count,) random factors on segment lengths, 1 +- lengthV."""
    variation = stem_params.length_variation
    return rng.uniform(1 - variation, 1 + variation, count) if variation else np.ones(count)


def _radius_at(start_radius: np.ndarray, end_radius: np.ndarray, fraction: float) -> np.ndarray:
    """Radii a `fraction` of the way from the stem start to its end (linear taper)."""
    return start_radius * (1 - fraction) + end_radius * fraction


# ---------------------------------------------------------------------------------------------- one level
def grow_level(stems: Level, params: WeberPennParams, order: int, *, close_tip: bool, rng: np.random.Generator,
               first_id: int = 0) -> Level:
    """Grow the stems of branch order `order`; with pruning on, each family's length is scaled down first until
    its tips fit the envelope. Spline ids are numbered from `first_id`."""
    level_seed = int(rng.integers(0, 2**63 - 1))
    length_scale = np.ones(stems.n_splines)
    if params.prune.enabled:
        length_scale = _pruned_length_scale(stems, params, order, close_tip=close_tip, level_seed=level_seed)
    level = _grow_splines(stems, params, order, length_scale=length_scale, close_tip=close_tip,
                          rng=np.random.default_rng(level_seed))
    return _numbered(level, first_id)


def _pruned_length_scale(stems: Level, params: WeberPennParams, order: int, *, close_tip: bool,
                         level_seed: int) -> np.ndarray:
    """(F,) factor on each family's length that brings its tips inside the envelope, by bisection; every trial
    grows from the same seed so only the length differs."""
    n_families = stems.n_splines
    prune_base = min(params.prune.base, params.base_size)
    scale = np.ones(n_families)
    low, high, previous_high = np.zeros(n_families), np.ones(n_families), np.ones(n_families)
    active = np.ones(n_families, bool)
    for _ in range(40):
        if not active.any():
            break
        finishing = active & (high - low < 0.01)
        scale = np.where(finishing, (scale - 1) * params.prune.ratio + 1, scale)
        trial = _grow_splines(stems, params, order, length_scale=scale, close_tip=close_tip,
                              rng=np.random.default_rng(level_seed))
        inside = np.ones(n_families, bool)
        np.logical_and.at(inside, trial.family, _inside_envelope(trial, params, order, prune_base))
        search = active & ~finishing
        shrink = search & ~inside
        previous_high = np.where(shrink, high, previous_high)
        high = np.where(shrink, scale, high)
        grow_back = search & inside & (scale != 1)
        low = np.where(grow_back, scale, low)
        high = np.where(grow_back, previous_high, high)
        low = np.where(search & inside & (high - low == 1), 1.0, low)
        scale = np.where(shrink | grow_back, 0.5 * (high + low), scale)
        active = search & (high - low > 0.005)
    return scale


def _inside_envelope(level: Level, params: WeberPennParams, order: int, prune_base: float) -> np.ndarray:
    """(S,) whether each spline's end lies inside Sapling's pruning envelope."""
    ends = level.points[np.arange(level.n_splines), level.first_step + level.n_points - 1]
    reach = np.hypot(ends[:, 0], ends[:, 1])
    scale = params.tree_scale
    ratio = (scale - ends[:, 2]) / (scale * max(1 - prune_base, 1e-6))
    prune = params.prune
    width = prune.width * shape_ratio(9, ratio, None, prune.width_peak, prune.power_high, prune.power_low)
    inside = reach / scale < width
    if order == 0:
        inside |= ends[:, 2] < prune_base * scale
    return inside


def _numbered(level: Level, first_id: int) -> Level:
    """Give the splines global ids from `first_id` and point each split at its parent spline's id."""
    is_split = level.parent_row >= 0
    level.spline_id = np.arange(level.n_splines) + first_id
    level.parent_spline = np.where(is_split, level.spline_id[np.maximum(level.parent_row, 0)], level.parent_spline)
    level.collar_points = np.where(level.collar[:, None], level.collar_points, level.points[:, 0])
    return level


def _grow_splines(stems: Level, params: WeberPennParams, order: int, *, length_scale: np.ndarray,
                  close_tip: bool, rng: np.random.Generator) -> Level:
    """Grow every stem of the level through all its segments; `length_scale` (S,) scales segment lengths."""
    level = replace(stems, **{name: values.copy() for name, values in stems.rows.items()})
    family_segment_length = stems.segment_length * length_scale  # Sapling's stemsegL: before the variation
    level.segment_length = family_segment_length * _length_factors(params.stem_levels[order],
                                                                   len(family_segment_length), rng)
    front = _GrowthFront.start(level, family_segment_length)
    for step in range(level.n_segments):
        level = _grow_segment(level, front, params, order, step=step, close_tip=close_tip, rng=rng)
    return level


def _grow_segment(level: Level, front: _GrowthFront, params: WeberPennParams, order: int, *, step: int,
                  close_tip: bool, rng: np.random.Generator) -> Level:
    """Grow every spline by the segment from `step` to `step + 1`; returns the level with its split-offs added."""
    n_segments = level.n_segments
    progress = step / (n_segments - 1) if n_segments > 1 else 1.0
    split_counts = _split_counts(level, front, params, order, step=step, progress=progress, rng=rng)
    curve_back = params.stem_levels[order].curve_back
    if step == int(n_segments / 2 + 0.5) and curve_back != 0:
        level.curvature += 2 * np.radians(curve_back) / n_segments
    splitting = split_counts > 0
    turns = _segment_turns(level, front, params, order, step=step, progress=progress, splitting=splitting,
                           rng=rng)
    front.bend_sign = -front.bend_sign
    directions = _continuing_directions(params, order, turns, splitting, n_segments)
    positions = front.positions + directions * (level.segment_length * turns.length_factor)[:, None]
    _set_segment_end(level, step, positions, close_tip)
    split_off = None
    if splitting.any():
        split_off = _split_off(level, front, turns, params, order, split_counts=split_counts, rng=rng)
    front.advance(positions, directions, splitting)
    if split_off is None:
        return level
    level = _append(level, split_off.rows)
    front.add(split_off)
    if level.n_splines > MAX_STEMS_PER_LEVEL:
        raise TreeTooLargeError(
            f"level {order} grew {level.n_splines} stems (limit {MAX_STEMS_PER_LEVEL}): segSplits[{order}] = "
            f"{params.stem_levels[order].seg_splits} and curveRes[{order}] = {n_segments} split too often; "
            f"lower them")
    return level


def _split_counts(level: Level, front: _GrowthFront, params: WeberPennParams, order: int, *, step: int,
                  progress: float, rng: np.random.Generator) -> np.ndarray:
    """(S,) int, how many stems split off each spline at `step` (Sapling: at most one, baseSplits at the trunk's
    first step)."""
    count = level.n_splines
    n_segments = level.n_segments
    if step == 0:
        return np.zeros(count, np.int64)
    if order == 0 and step < (n_segments - 1) * params.split_height and step != 1:
        return np.zeros(count, np.int64)
    if step == 1 and order == 0:
        return np.full(count, params.base_splits, np.int64)
    split_value = _split_value(params, order, progress, front.split_before)
    probability = split_value
    if order >= 1 and params.split_by_length:
        length_product = float(np.prod(params.stem_lengths()[: order + 1]))
        probability = split_value * (level.segment_length * n_segments / params.tree_scale) / length_product
    threshold = params.draws.split_threshold
    draw = threshold if threshold is not None else rng.random(count)
    splits = (draw < probability).astype(np.int64)
    if order == 0 and step == int((n_segments - 1) * params.split_height) + 1:  # the trunk's first split is forced
        splits = np.where(split_value > 0, 1, splits)
    return splits


def _split_value(params: WeberPennParams, order: int, progress: float, split_before: np.ndarray) -> np.ndarray:
    """(S,) Sapling's split probability: segSplits (biased along the trunk by splitBias), times 1.33 after a
    step without a split, squared after one."""
    seg_splits = params.stem_levels[order].seg_splits
    if order == 0:
        seg_splits = max(((2 * params.split_bias) * (progress - 0.5) + 1) * seg_splits, 0.0)
    return np.where(split_before == 0, seg_splits * 1.33, seg_splits * seg_splits)


def _segment_turns(level: Level, front: _GrowthFront, params: WeberPennParams, order: int, *, step: int,
                   progress: float, splitting: np.ndarray, rng: np.random.Generator) -> _SegmentTurns:
    """The step's frames, bends, split angles and length factors; records the splits' turns in `front`."""
    bend, bend_across = _bend_angles(level, params, order, progress=progress, bend_sign=front.bend_sign, rng=rng)
    frames = segment_frames(params, order, front.directions, front.positions, progress)
    angle, turn, spread = _split_turns(params, order, frames, splitting, front, rng)
    return _SegmentTurns(step=step, frames=frames, bend=bend, bend_across=bend_across, split_angle=angle,
                         turn=turn, spread=spread, length_factor=crown_taper(params, order, front.directions))


def _bend_angles(level: Level, params: WeberPennParams, order: int, *, progress: float,
                 bend_sign: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(S,) bend in the stem's plane and (S,) across it, radians: curvature plus the alternating variation
    (curveV1, curveV2; with Sapling's ranges uniform(0, curveV / curveRes) per spline and segment, in and
    across). The trunk below its split height does not curve."""
    n_segments = level.n_segments
    ranges = params.draws.ranges
    if ranges is not None and ranges.curve[order]:  # uniform(0, v): a negative curveV bends the other way
        in_plane, across = rng.random((2, level.n_splines)) * (ranges.curve[order] / n_segments)
    else:
        in_plane = params.draws.curve_variation[order] / n_segments
        across = params.draws.curve_variation_across[order] / n_segments
    straight = order == 0 and progress <= params.split_height
    curvature = np.zeros(level.n_splines) if straight else level.curvature
    return curvature + in_plane * progress * bend_sign, across * progress * bend_sign


def _split_turns(params: WeberPennParams, order: int, frames: np.ndarray, splitting: np.ndarray,
                 front: _GrowthFront, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S,) split angle, (S,) turn around the stem and (S,) spread, radians, for the splines that split now (0
    elsewhere); each splitting spline's turn is kept in `front.last_split_turn` for its next split."""
    count = len(splitting)
    angle, turn, spread = np.zeros(count), np.zeros(count), np.zeros(count)
    if not splitting.any():
        return angle, turn, spread
    ranges = params.draws.ranges
    n_splitting = int(splitting.sum())
    if ranges is None:
        angle[splitting] = split_angle(params, order)
        spread[splitting] = spread_angle(params, order)
    else:  # Sapling draws both per split: choice([-1, 1]) * (splitAngle + uniform(-splitAngleV, splitAngleV))
        angle[splitting], spread[splitting] = sapling_split_angles(params, order, n_splitting, rng)
    if order > 0:  # branches split less the more they lean
        lean = np.degrees(rot.declination(frames[splitting][:, :, 2]))
        angle[splitting] *= np.maximum(1 - lean / 90, 0) * 0.67 + 0.33
    last_turn = front.last_split_turn
    first_split = splitting & np.isnan(last_turn)
    if ranges is None:
        last_turn[first_split] = params.draws.first_split_turn[order]
        turn[splitting] = last_turn[splitting] + branch_turn(params)
    else:  # a stem's first split turns by uniform(0, 360 deg); each split by rotate[0] + uniform(-rotateV[0], ..)
        last_turn[first_split] = rng.uniform(0.0, TAU, int(first_split.sum()))
        trunk = params.stem_levels[0]
        turn_range = abs(ranges.trunk_turn)  # uniform(-v, v) is the same draw for v and -v
        turn[splitting] = last_turn[splitting] + np.radians(
            trunk.rotate + rng.uniform(-turn_range, turn_range, n_splitting))
    last_turn[splitting] = turn[splitting]
    return angle, turn, spread


def _continuing_directions(params: WeberPennParams, order: int, turns: _SegmentTurns, splitting: np.ndarray,
                           n_segments: int) -> np.ndarray:
    """(S, 3) unit direction of every spline's continuing stem (turned away from its split where it splits)."""
    local = bent_direction(np.where(splitting, -turns.split_angle, 0.0) + turns.bend, turns.bend_across)
    if order == 0:
        local = rot.premul("z", turns.turn, local)
    else:
        local = rot.premul("y", -turns.spread, local)
    return world_directions(params, order, turns.frames, local, n_segments)


def _set_segment_end(level: Level, step: int, positions: np.ndarray, close_tip: bool) -> None:
    """Write every spline's point at `step + 1` with its tapered radius (0 at a closed tip)."""
    radius = _radius_at(level.start_radius, level.end_radius, (step + 1) / level.n_segments)
    if close_tip and step == level.n_segments - 1:
        radius = np.zeros(level.n_splines)
    level.points[:, step + 1], level.radii[:, step + 1], level.valid[:, step + 1] = positions, radius, True


def _split_off(level: Level, front: _GrowthFront, turns: _SegmentTurns, params: WeberPennParams, order: int, *,
               split_counts: np.ndarray, rng: np.random.Generator) -> _SplitOff:
    """The splines that split off at this step (Sapling's growSpline with numSplit > 0), one per split."""
    splitting_rows = np.flatnonzero(split_counts > 0)
    per_row = split_counts[splitting_rows]
    parent = np.repeat(splitting_rows, per_row)
    index_in_row = np.arange(len(parent)) - np.repeat(np.cumsum(per_row) - per_row, per_row)
    length_factor = _length_factors(params.stem_levels[order], len(parent), rng)
    local = bent_direction(turns.split_angle[parent] + turns.bend[parent], turns.bend_across[parent])
    if order == 0:  # trunk splits fan out evenly around the stem
        around = np.pi - (TAU / (np.repeat(per_row, per_row) + 1)) * (index_in_row + 1)
        local = rot.premul("z", around + turns.turn[parent], local)
    else:
        local = rot.premul("y", turns.spread[parent], local)
    directions = world_directions(params, order, turns.frames[parent], local, level.n_segments)
    segment_length = front.family_segment_length[parent] * length_factor
    start = front.positions[parent]
    end = start + directions * (segment_length * turns.length_factor[parent])[:, None]
    radius_factor = np.minimum(length_factor * turns.length_factor[parent], 1.0)
    rows = _split_rows(level, parent, turns.step, segment_length=segment_length, radius_factor=radius_factor,
                       start=start, end=end, start_direction=directions)
    return _SplitOff(step=turns.step, rows=rows, directions=directions,
                     last_split_turn=turns.turn[parent] + np.pi,
                     family_segment_length=front.family_segment_length[parent])


def _split_rows(level: Level, parent: np.ndarray, step: int, *, segment_length: np.ndarray,
                radius_factor: np.ndarray, start: np.ndarray, end: np.ndarray, start_direction: np.ndarray) -> dict:
    """Level rows of splines that leave the rows `parent` at `step`, with their first segment `start` -> `end`."""
    n_segments = level.n_segments
    start_radius = level.start_radius[parent]
    end_radius = level.end_radius[parent]
    radius_now = _radius_at(start_radius, end_radius, step / n_segments) * radius_factor
    radius_next = _radius_at(start_radius, end_radius, (step + 1) / n_segments) * radius_factor
    count = len(parent)
    points = np.zeros((count, n_segments + 1, 3))
    radii = np.zeros((count, n_segments + 1))
    valid = np.zeros((count, n_segments + 1), bool)
    points[:, step], points[:, step + 1] = start, end
    radii[:, step], radii[:, step + 1] = radius_now, radius_next
    valid[:, step], valid[:, step + 1] = True, True
    n_points_before = level.valid[parent].sum(axis=1) - 1  # the step's new point is already in place
    return {
        "segment_length": segment_length, "curvature": level.curvature[parent],
        "start_radius": start_radius * radius_factor, "end_radius": end_radius * radius_factor,
        "children": level.children[parent], "family": level.family[parent],
        "first_step": np.full(count, step, np.int64),
        "offset_length": level.offset_length[parent] + level.segment_length[parent] * (n_points_before - 1),
        "collar": np.zeros(count, bool), "parent_spline": np.full(count, -1), "parent_row": parent,
        "parent_u": np.full(count, float(step)), "attach_points": start, "attach_radii": radius_now,
        "collar_points": start, "start_direction": start_direction, "points": points, "radii": radii,
        "valid": valid, "spline_id": np.arange(level.n_splines, level.n_splines + count),
    }
