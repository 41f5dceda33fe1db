"""Weber & Penn (1995) trees in the parameterisation of Blender's Sapling add-on (the one TreeSketchNet uses).

`grow(params, rng) -> Skeleton` takes a Sapling dictionary (70 keys, realized draws included) and grows every
stem of a level in lockstep, so the Python loops run over levels and curve segments, never over stems.

Our reading of TreeSketchNet's realized draws (Sapling would draw these itself): `scaleV` is the offset added to
`scale`, `scaleV0` the factor on the trunk radius, `leafScaleV` the factor on leaf size, `curveV1`/`curveV2`
(degrees per stem, per level) the curvature variation in and across the bending plane, `splitAngleV1/2` the
split and spread angle variations, `choiceNegPos1/2` their signs (0 or -1 = negative), `rLastAng` (degrees, per
level) the first split rotation, `rSplits2` the threshold a split probability must exceed. A dictionary without
them has them drawn from `rng`.
"""
from __future__ import annotations

import numpy as np

from ..geometry import rotations as rot
from ..growth import check_describes_a_tree
from ..skeleton import Skeleton
from .assembly import WeberPennTree, assemble
from .child_points import ChildPoints, child_points
from .leaves import leaf_transforms
from .params import StemLevelParams, WeberPennParams
from .sapling_keys import BLENDER_ONLY_KEYS, OLD_SAPLING_KEYS
from .schema import validate
from .shapes import shape_ratio
from .size_estimate import check_tree_size
from .stems import Level, grow_level

__all__ = ["grow", "grow_validated", "grow_tree"]

TAU = 2 * np.pi


def grow(params: dict, rng: np.random.Generator) -> Skeleton:
    """Grow a Weber-Penn tree from a Sapling dictionary; see the module docstring for the realized draws. One
    whose every key is ignored (Blender-only, old Sapling keys) describes no tree and is refused."""
    validated = validate(params)
    check_describes_a_tree(params, ignored=(*BLENDER_ONLY_KEYS, *OLD_SAPLING_KEYS))
    return grow_validated(validated, rng)


def grow_validated(validated: dict, rng: np.random.Generator) -> Skeleton:
    """Grow from `schema.validate`'s output (realized draws it lacks come from `rng`)."""
    return assemble(grow_tree(WeberPennParams.from_validated(validated, rng), rng))


def grow_tree(params: WeberPennParams, rng: np.random.Generator) -> WeberPennTree:
    """Every stem level in turn, then the leaves on the last level's child points; a tree whose estimated size
    exceeds the limits is refused (TreeTooLargeError) before anything grows."""
    check_tree_size(params)
    levels, last_points = _grow_levels(params, rng)
    if params.leaves.count and last_points is not None and len(last_points):
        transforms, pick = leaf_transforms(last_points, params, rng)
        return WeberPennTree(levels, transforms, last_points.spline[pick], last_points.u[pick])
    return WeberPennTree(levels, np.zeros((0, 4, 4)), np.zeros(0, np.int64), np.zeros(0))


def _grow_levels(params: WeberPennParams, rng: np.random.Generator) -> tuple[list, ChildPoints | None]:
    """The grown levels (trunk first) and the child points of the last one; stops early at a level with no
    stems (the leaves then hang on the level before)."""
    base_size = params.base_size
    grown, points, next_id = [], None, 0
    for order in range(params.levels):
        last = order == params.levels - 1
        if order == 0:
            stems = _trunk(params)
        else:
            stems = _fabricate(params, points, order, base_size=base_size, rng=rng)
            base_size *= params.base_size_shrink
        if last:
            base_size = 0.0
        if stems is None:
            break
        level = grow_level(stems, params, order, close_tip=last and params.close_tip, rng=rng, first_id=next_id)
        next_id += level.n_splines
        grown.append(level)
        points = child_points(level, params, order, base_size=base_size, rng=rng)
    return grown, points


# ---------------------------------------------------------------------------------------------- trunk
def _trunk(params: WeberPennParams) -> Level:
    trunk = params.stem_levels[0]
    length = params.tree_scale * trunk.length
    n_segments = trunk.curve_res
    children = params.leaves.count if params.levels == 1 else params.stem_levels[1].branches
    start = params.tree_scale * params.ratio * params.trunk_scale * params.draws.trunk_radius_factor
    end = max((start * (1 - trunk.taper)) ** params.ratio_power, params.min_radius)
    start = max(start, params.min_radius)
    return Level.new_stems(
        start_points=np.zeros((1, 3)), directions=np.array([[0.0, 0.0, 1.0]]),
        segment_length=np.array([length / n_segments]), curvature=np.array([np.radians(trunk.curve) / n_segments]),
        start_radius=np.array([start]), end_radius=np.array([end]), children=np.array([float(children)]),
        first_radius=np.array([start * params.root_flare]), parent_spline=np.array([-1]), parent_u=np.array([0.0]),
        collar=False, n_segments=n_segments)


# ---------------------------------------------------------------------------------------------- branches
def _fabricate(params: WeberPennParams, parent_points: ChildPoints, order: int, *, base_size: float,
               rng: np.random.Generator) -> Level | None:
    """Start the stems of level `order` at the child points of the level below (Sapling's fabricate_stems)."""
    base_size = min(0.999, base_size)
    aimed_turn = None
    if order == 1 and params.rotate_mode != "original" and len(parent_points):
        parent_points, aimed_turn = _pick_trunk_points(parent_points, params, base_size, rng)
    if len(parent_points) == 0:
        return None
    stem_params = params.stem_levels[order]
    down_angle = _down_angles(params, stem_params, parent_points, base_size, rng)
    turn = _child_rotations(stem_params, len(parent_points), rng)
    if aimed_turn is not None:
        turn = aimed_turn
    directions = _start_directions(params, order, parent_points, turn, down_angle)
    return _new_branches(params, order, parent_points, directions, base_size)


def _down_angles(params: WeberPennParams, stem_params: StemLevelParams, points: ChildPoints, base_size: float,
                 rng: np.random.Generator) -> np.ndarray:
    """(P,) radians between each new stem and its parent (0 for a stem continuing a parent's tip)."""
    count = len(points)
    down, down_variation = np.radians(stem_params.down_angle), np.radians(stem_params.down_angle_variation)
    from_top = (1 - points.offset) / (1 - base_size)
    if params.old_down_angle:
        if down_variation < 0:
            variation = down_variation * (1 - 2 * (0.2 + 0.8 * from_top))
        else:
            variation = rng.uniform(-down_variation, down_variation, count) if down_variation else np.zeros(count)
    elif down_variation < 0:
        variation = rng.uniform(down_variation, -down_variation, count)
    else:
        variation = -down_variation * (1 - from_top) ** 2
    return np.where(points.offset == 1, 0.0, down + variation)


def _child_rotations(stem_params: StemLevelParams, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count,) radians, successive stems' rotation around their parent: rotate apart (alternating sides when
    rotate < 0), plus rotateV's variation."""
    rotate, variation = np.radians(stem_params.rotate), np.radians(stem_params.rotate_variation)
    if rotate < 0:
        base = -abs(rotate) * np.where(np.arange(count) % 2 == 0, 1.0, -1.0)
    else:
        base = rotate * np.arange(1, count + 1)
    return base + (rng.uniform(-abs(variation), abs(variation), count) if variation else 0.0)


def _start_directions(params: WeberPennParams, order: int, points: ChildPoints, turn: np.ndarray,
                      down_angle: np.ndarray) -> np.ndarray:
    """(P, 3) world directions of new stems turned by `turn` around and `down_angle` away from the parent.

    First-level branches in 'rotate' mode turn in the world frame, leaning with the trunk (useParentAngle).
    """
    at_tip = points.offset == 1
    local = rot.apply(rot.rot_z(turn) @ rot.rot_x(down_angle), np.tile([0.0, 0.0, 1.0], (len(points), 1)))
    frames = rot.track_frames(points.tangent)
    if not (order == 1 and params.rotate_mode == "rotate"):
        return rot.apply(frames, local)
    world = local.copy()
    leaning = ~at_tip
    if params.parent_angle and leaning.any():
        azimuth = rot.euler_xyz(frames[leaning], turn[leaning])[:, 2]
        lean = rot.declination(points.tangent[leaning])
        tilt = rot.rot_z(azimuth) @ rot.rot_x(lean) @ rot.rot_z(-azimuth)
        world[leaning] = rot.apply(tilt, local[leaning])
    world[at_tip] = rot.apply(frames[at_tip], local[at_tip])
    return world


def _new_branches(params: WeberPennParams, order: int, points: ChildPoints, directions: np.ndarray,
                  base_size: float) -> Level | None:
    """The level's new stems: lengths by the crown shape, radii by the pipe rule, zero-length ones dropped."""
    stem_params = params.stem_levels[order]
    max_length = params.tree_scale * np.prod(params.stem_lengths()[: order + 1])
    ratio = (1 - points.stem_offset) / (1 - base_size)
    if order == 1:
        shape = shape_ratio(params.shape, ratio, params.custom_shape)
    else:
        shape = shape_ratio(params.side_shape, ratio)
    length = points.parent_length * stem_params.length * shape
    relative_length = 0.1 + 0.9 * length / max_length
    if order == params.levels - 1:  # the last level carries the leaves
        leaves = params.leaves
        children = (np.zeros(len(points)) if leaves.count < 0 else
                    leaves.count * relative_length * shape_ratio(leaves.distribution, 1 - points.offset))
    else:
        children = params.stem_levels[min(3, order + 1)].branches * relative_length
    start_radius, end_radius = _branch_radii(params, stem_params, points, length)
    keep = np.flatnonzero(length > 1e-5 * params.tree_scale)  # a zero-length stem has no geometry
    if len(keep) == 0:
        return None
    n_segments = stem_params.curve_res
    return Level.new_stems(
        start_points=points.position[keep], directions=directions[keep], segment_length=length[keep] / n_segments,
        curvature=np.full(len(keep), np.radians(stem_params.curve) / n_segments), start_radius=start_radius[keep],
        end_radius=end_radius[keep], children=children[keep], first_radius=start_radius[keep],
        parent_spline=points.spline[keep], parent_u=points.u[keep], collar=True, n_segments=n_segments,
        parent_radius=points.parent_radius[keep])


def _branch_radii(params: WeberPennParams, stem_params: StemLevelParams, points: ChildPoints,
                  length: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P,) start and (P,) end radius, metres: the parent's radius scaled by (length ratio) ** ratioPower, never
    thicker than the parent where the stem leaves it, never below minRadius."""
    with np.errstate(divide="ignore", invalid="ignore"):
        start = np.minimum(points.parent_start_radius * (length / points.parent_length) ** params.ratio_power
                           * stem_params.radius_tweak, points.parent_radius)
    start = np.where(points.offset == 1, points.parent_radius, start)
    end = np.maximum((start * (1 - stem_params.taper)) ** params.ratio_power, params.min_radius)
    return np.maximum(start, params.min_radius), end


def _pick_trunk_points(points: ChildPoints, params: WeberPennParams, base_size: float,
                       rng: np.random.Generator) -> tuple[ChildPoints, np.ndarray]:
    """Sapling's 'rotate' and 'random' modes for first-level branches: one sprout per height (the one nearest the
    height's rotation angle, or a random one), and in 'rotate' mode the turn that aims it there."""
    tips = np.flatnonzero(points.offset == 1)
    inner = np.flatnonzero(points.offset != 1)
    if len(inner) == 0:
        return points.take(tips), np.zeros(len(tips))
    heights, group = np.unique(points.offset[inner], return_inverse=True)
    turn = _child_rotations(params.stem_levels[1], len(heights), rng)
    aiming = params.rotate_mode == "rotate"
    if aiming:
        chosen = _nearest_to_turn(points.position[inner], turn, group)
    else:
        chosen = _random_per_height(group, len(heights), rng)
    pick = inner[chosen]  # one per height, heights ascending
    aimed = _aimed_turns(points.take(pick), params, turn, base_size) if aiming else np.zeros(len(pick))
    return points.take(np.concatenate([pick, tips])), np.concatenate([aimed, np.zeros(len(tips))])


def _nearest_to_turn(positions: np.ndarray, turn: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Index of the point of each group whose azimuth is nearest its group's `turn`, groups ascending."""
    wanted = np.mod(turn, TAU)[group]
    azimuth = np.arctan2(positions[:, 0], -positions[:, 1])
    difference = np.minimum(np.mod(wanted - azimuth + TAU, TAU), np.mod(azimuth - wanted + TAU, TAU))
    ranked = np.lexsort((np.arange(len(positions)), difference, group))
    first = np.ones(len(ranked), bool)
    first[1:] = group[ranked][1:] != group[ranked][:-1]
    return ranked[first]


def _random_per_height(group: np.ndarray, n_groups: int, rng: np.random.Generator) -> np.ndarray:
    """Index of one random point per group, groups ascending."""
    counts = np.bincount(group, minlength=n_groups)
    starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
    by_group = np.argsort(group, kind="stable")
    return by_group[starts + rng.integers(0, counts)]


def _aimed_turns(picked: ChildPoints, params: WeberPennParams, turn: np.ndarray, base_size: float) -> np.ndarray:
    """(P,) radians that turn each picked first-level branch so its tip heads toward its height's `turn`."""
    base = picked.position
    reach = np.hypot(base[:, 0], base[:, 1])
    ratio = (1 - picked.offset) / (1 - base_size)
    first_level = params.stem_levels[1]
    length = picked.parent_length * first_level.length * shape_ratio(params.shape, ratio, params.custom_shape)
    down = np.radians(first_level.down_angle)
    if first_level.down_angle_variation > 0:
        down = down - np.radians(first_level.down_angle_variation) * (1 - ratio) ** 2
    down = np.broadcast_to(down, length.shape)
    length = np.where(down < 0.5 * np.pi, length * np.sin(down) ** 2, length) * 0.33
    target = np.stack([np.sin(turn), np.cos(turn)], axis=1) * (reach + length)[:, None]
    return np.arctan2(target[:, 0] - base[:, 0], target[:, 1] + base[:, 1])
