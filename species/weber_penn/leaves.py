"""Leaf placements of a Weber-Penn tree (Sapling's genLeafMesh) as 4x4 transforms of the unit leaf card.

In: the child points of the last stem level. Out: (M, 4, 4) transforms and, per leaf, the child point it hangs on.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import rotations as rot
from .child_points import ChildPoints
from .params import LeafParams, WeberPennParams

__all__ = ["leaf_transforms"]


@dataclass(frozen=True)
class _Placement:
    """Where and how each of M leaves sits before its card is turned and sized."""

    pick: np.ndarray         # (M,) int, the child point each leaf hangs on
    frames: np.ndarray       # (M, 3, 3) the stem's tracking frame there
    orientation: np.ndarray  # (M, 3, 3) the leaf's turn in that frame
    after: np.ndarray        # (M,) radians, the leaf's rotation around the stem (decides the card's side)
    along: np.ndarray        # (M,) where the leaf is along its stem or fan, 0..1 (drives leafScaleT)


def leaf_transforms(points: ChildPoints, params: WeberPennParams,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(M, 4, 4) float32 leaf transforms and (M,) int the child point each hangs on; leaves of zero size are left
    out."""
    leaves = params.leaves
    placement = _fanned(points, leaves, rng) if leaves.count < 0 else _spiralled(points, leaves, rng)
    rotation = placement.frames @ placement.orientation @ _card_turn(leaves, placement.after)
    size_factor = params.draws.leaf_size_factor
    ranges = params.draws.ranges
    if ranges is not None and ranges.leaf_scale:  # Sapling: each leaf's size times uniform(1 - v, 1 + v)
        size_factor = rng.uniform(1 - ranges.leaf_scale, 1 + ranges.leaf_scale, len(placement.pick))
    size = _leaf_sizes(leaves, placement.along, size_factor)
    keep = size > 0
    pick = placement.pick
    if not keep.all():
        pick, size, rotation = pick[keep], size[keep], rotation[keep]
    # Written straight into float32, the skeleton's dtype: the same rounding as casting a float64 array after.
    transforms = np.zeros((len(pick), 4, 4), np.float32)
    transforms[:, :3, :3] = rotation * np.stack([size * leaves.scale_x, size, size], axis=1)[:, None, :]
    transforms[:, :3, 3] = points.position[pick]
    transforms[:, 3, 3] = 1.0
    return transforms, pick


def _fanned(points: ChildPoints, leaves: LeafParams, rng: np.random.Generator) -> _Placement:
    """A fan of -leaves leaves at every point, spread over leafRotate (alternating sides when it is < 0)."""
    rotate, rotate_variation = np.radians(leaves.rotate), np.radians(leaves.rotate_variation)
    fan = -leaves.count
    pick = np.repeat(np.arange(len(points)), fan)
    in_fan = np.tile(np.arange(fan), len(points))
    count = len(pick)
    step = rotate / (fan - 1) if fan > 1 else 0.0
    if rotate < 0:
        variation = rng.uniform(-abs(rotate_variation), abs(rotate_variation), count) if rotate_variation else 0.0
        magnitude = np.abs(rotate + variation)
        before = np.where(in_fan == 0, -rotate / 2, magnitude * np.where(in_fan % 2 == 1, -1.0, 1.0))
        after = -np.copysign(magnitude, before)
        fan_turn = before
    elif fan == 1:
        after = np.full(count, -rotate / 2)
        fan_turn = np.zeros(count)
    else:
        fan_turn = -rotate / 2 + in_fan * step
        after = fan_turn + step
    along = 1 - np.abs((after - step) / (rotate / 2)) if (fan > 1 and rotate > 0) else points.offset[pick]
    return _Placement(pick=pick, frames=rot.track_frames(points.tangent)[pick], orientation=rot.rot_y(fan_turn),
                      after=after, along=along)


def _spiralled(points: ChildPoints, leaves: LeafParams, rng: np.random.Generator) -> _Placement:
    """One leaf per point, each turned leafRotate past the previous one and leafDownAngle off the stem."""
    rotate, rotate_variation = np.radians(leaves.rotate), np.radians(leaves.rotate_variation)
    down, down_variation = np.radians(leaves.down_angle), np.radians(leaves.down_angle_variation)
    count = len(points)
    variation = (rng.uniform(-abs(rotate_variation), abs(rotate_variation), count) if rotate_variation
                 else np.zeros(count))
    if rotate < 0:
        after = np.abs(rotate + variation) * np.where(np.arange(count) % 2 == 0, -1.0, 1.0)
    else:
        after = np.cumsum(rotate + variation)
    before = np.concatenate([[0.0], after[:-1]])
    if down_variation > 0:
        down_offset = -down_variation * points.offset
    else:
        down_offset = rng.uniform(down_variation, -down_variation, count) if down_variation else np.zeros(count)
    horizontal = -after + rotate if (rotate > 0 and leaves.horizontal) else 0.0  # zxz broadcasts a scalar
    return _Placement(pick=np.arange(count), frames=rot.track_frames(points.tangent),
                      orientation=rot.zxz(before, down + down_offset, horizontal), after=after, along=points.offset)


def _card_turn(leaves: LeafParams, after: np.ndarray) -> np.ndarray:
    """(3, 3) or (M, 3, 3): Sapling turns the card 180 degrees about z and tilts it by -leafangle; with a negative
    leafRotate it also turns it a quarter toward the side the leaf sits on."""
    card = rot.rot_x(np.radians(-leaves.tilt))[0] @ rot.rot_z(np.pi)[0]
    if leaves.rotate < 0:
        card = np.where((after < 0)[:, None, None], rot.rot_z(1.5 * np.pi)[0] @ card,
                        rot.rot_z(0.5 * np.pi)[0] @ card)
    return card


def _leaf_sizes(leaves: LeafParams, along: np.ndarray, size_factor: float | np.ndarray) -> np.ndarray:
    """(M,) metres, leaf card length: leafScale tapered along the stem by leafScaleT, times the realized draw
    (one for the tree, or one per leaf)."""
    taper = leaves.scale_taper
    size = leaves.scale * ((1 - (1 - along) * -taper) if taper < 0 else (1 - along * taper)) * size_factor
    return np.abs(size)
