"""Directions of Weber-Penn stem segments: each spline's frame, its bend in that frame, the angles of its splits,
and the vertical attraction that turns the result toward (or away from) world up.

In: the parameters, a branch order and (S, 3) unit directions or (S, 3, 3) frames. Out: arrays over S splines.
"""
from __future__ import annotations

import numpy as np

from ..geometry import rotations as rot
from ..geometry.vectors import unit_vectors
from .params import WeberPennParams

__all__ = ["attract_up", "bent_direction", "world_directions", "split_angle", "spread_angle",
           "sapling_split_angles", "branch_turn", "segment_frames", "crown_taper"]

TAU = 2 * np.pi


def attract_up(directions: np.ndarray, attraction: float, n_segments: int) -> np.ndarray:
    """Sapling's vertical attraction: turn each unit direction toward (or, if negative, away from) world up.

    Sapling turns about the tracking frame's x axis, by attractUp * declination * |frame y . up| / curveRes;
    that frame's y is world up projected off the direction, so the turn is in the vertical plane.
    """
    if attraction == 0:
        return directions
    dz = np.clip(directions[:, 2], -1.0, 1.0)
    sin_declination = np.sqrt(1.0 - dz * dz)
    declination = np.arccos(dz)
    angle = attraction * declination * sin_declination / n_segments
    angle = np.where(-declination + angle < -np.pi, -np.pi + declination, angle)
    angle = np.where(declination - angle < 0, declination, angle)
    up = -dz[:, None] * directions
    up[:, 2] += 1.0
    up /= np.where(sin_declination > 1e-12, sin_declination, 1.0)[:, None]
    return np.cos(angle)[:, None] * directions + np.sin(angle)[:, None] * up


def bent_direction(bend: np.ndarray, across: np.ndarray) -> np.ndarray:
    """(N, 3) = Ry(across) @ Rx(bend) @ z: a stem's next direction in its own frame."""
    cos_bend = np.cos(bend)
    return np.stack([cos_bend * np.sin(across), -np.sin(bend), cos_bend * np.cos(across)], axis=1)


def world_directions(params: WeberPennParams, order: int, frames: np.ndarray, local: np.ndarray,
                     n_segments: int) -> np.ndarray:
    """(N, 3) unit world directions of `local` ones in `frames`, after the level's vertical attraction."""
    world = rot.apply(frames, local)
    return unit_vectors(attract_up(world, params.stem_levels[order].attract_up, n_segments))


def split_angle(params: WeberPennParams, order: int) -> float:
    """Radians between a split and the stem it leaves: splitAngle with its realized variation and sign."""
    draws = params.draws
    return draws.split_angle_sign * (np.radians(params.stem_levels[order].split_angle)
                                     + draws.split_angle_variation[order])


def spread_angle(params: WeberPennParams, order: int) -> float:
    """Radians a branch split turns away from the splitting plane: splitAngle with the spread variation."""
    draws = params.draws
    return draws.spread_angle_sign * (np.radians(params.stem_levels[order].split_angle)
                                      + draws.spread_angle_variation[order])


def sapling_split_angles(params: WeberPennParams, order: int, count: int,
                         rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(count,) split and (count,) spread angles, radians, drawn as Sapling draws them for each split of a
    `draws: ranges` dictionary: each a random sign times splitAngle + uniform(-splitAngleV, splitAngleV)."""
    base = np.radians(params.stem_levels[order].split_angle)
    variation = abs(params.draws.ranges.split_angle[order])  # uniform(-v, v) is the same draw for v and -v
    signs = rng.choice(np.array([-1.0, 1.0]), (2, count))
    offsets = rng.uniform(-variation, variation, (2, count)) if variation else np.zeros((2, count))
    split, spread = signs * (base + offsets)
    return split, spread


def branch_turn(params: WeberPennParams) -> float:
    """Radians each split turns around its stem beyond the previous one: Sapling uses the trunk's rotate."""
    trunk = params.stem_levels[0]
    return np.radians(trunk.rotate + trunk.rotate_variation)


def segment_frames(params: WeberPennParams, order: int, directions: np.ndarray, positions: np.ndarray,
                   progress: float) -> np.ndarray:
    """(S, 3, 3) each spline's frame for its next segment: the trunk's without roll, a branch's tracking world up
    and turned away from the trunk axis by attractOut."""
    if order == 0:
        return rot.tilt_frames(directions)
    frames = rot.track_frames(directions)
    attract_out = params.stem_levels[order].attract_out
    if progress > 0 and attract_out > 0:
        azimuth = np.arctan2(positions[:, 0], -positions[:, 1]) + TAU
        euler = rot.euler_xyz(frames, azimuth)
        pull = progress * attract_out
        x = np.sin(euler[:, 2]) + (np.sin(azimuth) - np.sin(euler[:, 2])) * pull
        y = np.cos(euler[:, 2]) + (np.cos(azimuth) - np.cos(euler[:, 2])) * pull
        euler[:, 2] = np.arctan2(x, y)
        frames = rot.from_euler_xyz(euler)
    return frames


def crown_taper(params: WeberPennParams, order: int, directions: np.ndarray) -> np.ndarray:
    """(S,) factor on the segment length: taperCrown shortens leaning trunk segments (1 for branches)."""
    if order != 0:
        return np.ones(len(directions))
    lean = np.degrees(rot.declination(directions)) / 180
    return np.maximum(0.1, 1 - lean ** 2 * params.taper_crown * 30)
