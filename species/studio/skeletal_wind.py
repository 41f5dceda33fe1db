"""Baked skeletal wind: a joint hierarchy on a tree's wind pivots (the trunk in segments, then first- and
second-order branches within a joint budget), skin weights (at most 4 joints a vertex, blended across joints),
the joint each leaf follows, and a seamless looping clip of joint rotations made from the wind shader's layers.

In: the LOD0 Skeleton and WindClipSettings. Out: `WindRig` (rest pose, Z up, metres), `skin_weights` arrays,
`WindClip` (local joint rotations per sample, seconds). The clip follows `farm/library/wind_example.html`'s shader:
the trunk leans downwind quadratically with height in a slow gust, each branch swings about its pivot, faster and
wider the finer it is, in its own phase; every rate is rounded to a whole number of cycles per clip so the clip
loops. Leaf flutter (per leaf) has no joint to ride on and stays the shader's.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry.vectors import cross_rows, row_norms, unit_vectors
from ..skeleton import Skeleton
from .wind import branch_phases, branch_pivots, branch_reaches

__all__ = ["WindClipSettings", "WindRig", "WindClip", "wind_rig", "skin_weights", "follow_joints", "wind_clip",
           "joint_world_poses", "shader_wind_offset", "loop_rate", "rotation_vector_quaternions",
           "TRUNK_SEGMENTS", "DEFAULT_JOINT_BUDGET", "JOINT_BUDGET_RANGE", "SAMPLES_PER_SECOND", "WIND_DIRECTION",
           "WIND_ACROSS", "MAX_INFLUENCES"]

TRUNK_SEGMENTS = 4
DEFAULT_JOINT_BUDGET = 64
# glTF JOINTS_0 as unsigned bytes holds indices up to 255; the budget can never be fewer joints than the trunk's.
JOINT_BUDGET_RANGE = (TRUNK_SEGMENTS, 256)
MAX_INFLUENCES = 4
SAMPLES_PER_SECOND = 15  # keys per second: the finest branches swing about once every two seconds
# Share of a jointed branch's length (from its pivot) over which its vertices blend from the parent's joints.
_BLEND_ALONG = 0.25
# The shader's constants (wind_example.html: windLean, windOffset); the wind blows along +x, 0.3 across, in its
# Y-up frame, which is (1, -0.3, 0) normalised in our Z-up frame.
LEAN_PER_STRENGTH = 0.04
GUST_RATE = 0.8  # rad/s
SWING_BASE, SWING_PER_LEVEL = 0.05, 0.04
BEAT_BASE, BEAT_PER_LEVEL = 1.5, 0.6  # rad/s
ACROSS_BEAT = 1.3
ACROSS_SHARE, DROOP_SHARE = 0.5, 0.3
WIND_DIRECTION = np.array([1.0, -0.3, 0.0]) / np.hypot(1.0, 0.3)
WIND_ACROSS = np.array([-0.3, -1.0, 0.0]) / np.hypot(1.0, 0.3)  # the shader's (-0.3, 0, 1), Y up
_UP = np.array([0.0, 0.0, 1.0])
_LEAN_AXIS = np.cross(_UP, WIND_DIRECTION)  # turning +z about it leans the tree downwind


@dataclass(frozen=True)
class WindClipSettings:
    """The clip's wind: strength (0 still, 1 a strong wind; the shader page's slider), gust (share of the lean
    that comes and goes with the gust, in [0, 1]), period_s (seconds of one loop), joint_budget (joints at most)."""

    strength: float = 0.5
    gust: float = 0.4
    period_s: float = 6.0
    joint_budget: int = DEFAULT_JOINT_BUDGET


@dataclass(frozen=True)
class WindRig:
    """Joints in their rest pose (identity rotations), parents before children.

    names     : J joint names, `trunk_<k>` then `branch_<LOD0 branch index>`.
    parent    : (J,) int64, parent joint (-1 for trunk_0).
    position  : (J, 3) float64, metres, Z up: the joint's pivot.
    level     : (J,) int64, branch order (0 on the trunk's joints and on stems split off it).
    phase     : (J,) float64 in [0, 1), the branch's wind phase (`branch_phases`, the shader's w.z).
    direction : (J, 3) float64, unit vector from the pivot to the branch's farthest node (+z on the trunk).
    reach     : (J,) float64, metres from the pivot to the branch's farthest node.
    height    : metres, the tree's height (the shader's windHeight).
    own_joint : (B,) int64, the joint of each LOD0 branch, -1 for branches that ride on an ancestor's.
    anchor_joints, anchor_weights : (B, 4) int64 / float64, the skin weights where each branch leaves its parent.
    pivots, reaches : (B, 3) / (B,) float64, each LOD0 branch's pivot and reach.
    trunk_branch : (B,) bool, branches skinned to the trunk's segments (those without a parent).
    """

    names: tuple[str, ...]
    parent: np.ndarray
    position: np.ndarray
    level: np.ndarray
    phase: np.ndarray
    direction: np.ndarray
    reach: np.ndarray
    height: float
    own_joint: np.ndarray
    anchor_joints: np.ndarray
    anchor_weights: np.ndarray
    pivots: np.ndarray
    reaches: np.ndarray
    trunk_branch: np.ndarray

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def local_translation(self) -> np.ndarray:
        """(J, 3) float64, metres, Z up: each joint's offset from its parent (from the origin for trunk_0)."""
        parent_position = np.where(self.parent[:, None] >= 0, self.position[np.maximum(self.parent, 0)], 0.0)
        return self.position - parent_position


@dataclass(frozen=True)
class WindClip:
    """times (K,) float64 seconds from 0 to the period (the last key repeats the first); rotations (K, J, 4)
    float64 unit quaternions (x, y, z, w) of each joint relative to its parent, Z up; impostor (K, 4) the whole
    tree's lean about its base, for a level drawn as one card."""

    times: np.ndarray
    rotations: np.ndarray
    impostor: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.times[-1])


def loop_rate(rate, period: float):
    """The angular rates (rad/s) nearest `rate` (a number or an array) that make a whole number (>= 1) of cycles
    in `period` seconds."""
    cycles = np.maximum(1.0, np.rint(np.asarray(rate, np.float64) * period / (2.0 * np.pi)))
    return cycles * 2.0 * np.pi / period


def _trunk_points(skeleton: Skeleton, reach: float) -> np.ndarray:
    """(TRUNK_SEGMENTS, 3) float64: where the trunk's straight distance from its base is k / TRUNK_SEGMENTS of
    its reach, k = 0.. (the `along` of the wind data, so bark weights and joints agree)."""
    path = skeleton.branch_paths[0]
    points = skeleton.positions[path].astype(np.float64)
    distance = np.maximum.accumulate(row_norms(points - points[0]))
    targets = reach * np.arange(TRUNK_SEGMENTS) / TRUNK_SEGMENTS
    return np.stack([np.interp(targets, distance, points[:, axis]) for axis in range(3)], axis=1)


def _branch_depths(parent: np.ndarray) -> np.ndarray:
    """(B,) int64 ancestors of each branch (0 for branches without a parent)."""
    depth = np.where(parent < 0, 0, -1)
    while (depth < 0).any():
        ready = (depth < 0) & (depth[np.maximum(parent, 0)] >= 0)
        depth[ready] = depth[parent[ready]] + 1
    return depth


def _top_influences(joints: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, k) candidate joints and weights (joints distinct within a row) to the MAX_INFLUENCES largest, heaviest
    first, normalised to sum 1; unused slots joint 0 with weight 0."""
    order = np.lexsort((joints, -weights), axis=1)[:, :MAX_INFLUENCES]
    joints = np.take_along_axis(joints, order, axis=1)
    weights = np.take_along_axis(weights, order, axis=1)
    if weights.shape[1] < MAX_INFLUENCES:
        pad = MAX_INFLUENCES - weights.shape[1]
        joints = np.pad(joints, ((0, 0), (0, pad)))
        weights = np.pad(weights, ((0, 0), (0, pad)))
    weights = weights / np.maximum(weights.sum(axis=1, keepdims=True), 1e-12)
    return np.where(weights > 0, joints, 0), weights


def _trunk_weights(along: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Linear blend between the two trunk joints whose segment middles bracket `along` (n,) in [0, 1]."""
    t = np.clip(along * TRUNK_SEGMENTS - 0.5, 0.0, TRUNK_SEGMENTS - 1.0)
    low = np.minimum(np.floor(t).astype(np.int64), TRUNK_SEGMENTS - 2)
    share = np.clip(t - low, 0.0, 1.0)
    joints = np.stack([low, np.minimum(low + 1, TRUNK_SEGMENTS - 1)], axis=1)
    return _top_influences(joints, np.stack([1.0 - share, share], axis=1))


def _weights_on(branch: np.ndarray, along: np.ndarray, own_joint, anchor_joints, anchor_weights,
                trunk_branch) -> tuple[np.ndarray, np.ndarray]:
    """Skin weights (n, 4) of points on LOD0 branches (n,) at `along` (n,) their share of the branch's reach."""
    joints = np.zeros((len(branch), MAX_INFLUENCES), np.int64)
    weights = np.zeros((len(branch), MAX_INFLUENCES))
    on_trunk = trunk_branch[branch]
    if on_trunk.any():
        joints[on_trunk], weights[on_trunk] = _trunk_weights(along[on_trunk])
    rest = ~on_trunk
    own = own_joint[branch[rest]]
    blend = np.clip(along[rest] / _BLEND_ALONG, 0.0, 1.0)
    blend = np.where(own >= 0, blend * blend * (3.0 - 2.0 * blend), 0.0)  # smoothstep: no crease at the joint
    candidates = np.concatenate([np.maximum(own, 0)[:, None], anchor_joints[branch[rest]]], axis=1)
    shares = np.concatenate([blend[:, None], (1.0 - blend)[:, None] * anchor_weights[branch[rest]]], axis=1)
    joints[rest], weights[rest] = _top_influences(candidates, shares)
    return joints, weights


def wind_rig(skeleton: Skeleton, joint_budget: int = DEFAULT_JOINT_BUDGET) -> WindRig:
    """The joint hierarchy of a LOD0 skeleton: TRUNK_SEGMENTS joints up the trunk, then stems split off it and
    first- and second-order branches by size (reach times base radius), a branch only when its parent is the
    trunk or has a joint, until `joint_budget` joints. Deterministic: ties go to the lower branch index."""
    if joint_budget < TRUNK_SEGMENTS:
        raise ValueError(f"joint_budget {joint_budget} is under the trunk's {TRUNK_SEGMENTS} segments")
    pivots = skeleton.positions[branch_pivots(skeleton)].astype(np.float64)
    reaches = branch_reaches(skeleton)
    starts = skeleton.branch_starts
    parent = skeleton.branch_parent
    level = skeleton.order[starts].astype(np.int64)
    trunk_branch = parent < 0
    # The farthest node of each branch from its pivot gives the direction its swing turns.
    distance = row_norms(skeleton.positions.astype(np.float64) - pivots[skeleton.branch_id])
    far = np.lexsort((np.arange(len(distance)), -distance, skeleton.branch_id))
    first = np.searchsorted(skeleton.branch_id[far], np.arange(skeleton.n_branches))
    tips = skeleton.positions[far[first]].astype(np.float64)

    chosen = np.zeros(skeleton.n_branches, bool)
    score = reaches * skeleton.radius[starts].astype(np.float64)
    # Stems split off the trunk (order 0) lean with it; first- and second-order branches also sway.
    candidates = np.flatnonzero((level <= 2) & ~trunk_branch & (reaches > 0))
    room = joint_budget - TRUNK_SEGMENTS
    for b in candidates[np.lexsort((candidates, -score[candidates]))]:  # at most B steps, stops at the budget
        if room == 0:
            break
        if trunk_branch[parent[b]] or chosen[parent[b]]:
            chosen[b] = True
            room -= 1
    jointed = np.flatnonzero(chosen)
    own_joint = np.full(skeleton.n_branches, -1, np.int64)
    own_joint[jointed] = TRUNK_SEGMENTS + np.arange(len(jointed))

    trunk_reach = float(reaches[0])
    trunk_points = _trunk_points(skeleton, trunk_reach)
    # Anchors: parents first (by ancestor count), each the weights on its parent where it leaves it.
    anchor_joints = np.zeros((skeleton.n_branches, MAX_INFLUENCES), np.int64)
    anchor_weights = np.zeros((skeleton.n_branches, MAX_INFLUENCES))
    anchor_weights[:, 0] = 1.0
    depth = _branch_depths(parent)
    for d in range(1, int(depth.max()) + 1):
        now = np.flatnonzero(depth == d)
        host = parent[now]
        along = np.clip(row_norms(pivots[now] - pivots[host]) / np.maximum(reaches[host], 1e-9), 0.0, 1.0)
        anchor_joints[now], anchor_weights[now] = _weights_on(host, along, own_joint, anchor_joints,
                                                              anchor_weights, trunk_branch)
    # A branch joint hangs from the heaviest joint where its branch leaves its parent.
    joint_parent = np.concatenate([np.arange(TRUNK_SEGMENTS) - 1, anchor_joints[jointed, 0]])
    trunk_direction = unit_vectors(tips[:1] - pivots[:1]) if trunk_reach > 0 else _UP[None]
    return WindRig(
        names=tuple([f"trunk_{k}" for k in range(TRUNK_SEGMENTS)] + [f"branch_{b}" for b in jointed]),
        parent=joint_parent.astype(np.int64),
        position=np.concatenate([trunk_points, pivots[jointed]]),
        level=np.concatenate([np.zeros(TRUNK_SEGMENTS, np.int64), level[jointed]]),
        phase=np.concatenate([np.zeros(TRUNK_SEGMENTS), branch_phases(starts[jointed]).astype(np.float64)]),
        direction=np.concatenate([np.repeat(trunk_direction, TRUNK_SEGMENTS, axis=0),
                                  unit_vectors(tips[jointed] - pivots[jointed])]),
        reach=np.concatenate([np.full(TRUNK_SEGMENTS, trunk_reach / TRUNK_SEGMENTS), reaches[jointed]]),
        height=float(skeleton.height), own_joint=own_joint, anchor_joints=anchor_joints,
        anchor_weights=anchor_weights, pivots=pivots, reaches=reaches, trunk_branch=trunk_branch)


def skin_weights(rig: WindRig, points: np.ndarray, branch: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Skin weights of vertices: points (V, 3) metres Z up, branch (V,) their LOD0 branch. Returns joints (V, 4)
    uint8 (heaviest first) and weights (V, 4) float32 summing to 1. A vertex on a jointed branch blends from
    its parent's joints to the branch's own over the branch's first quarter; the trunk blends between its
    segments; a branch without a joint moves with its parent where it leaves it."""
    branch = np.asarray(branch, np.int64)
    along = row_norms(np.asarray(points, np.float64) - rig.pivots[branch]) / np.maximum(rig.reaches[branch], 1e-9)
    joints, weights = _weights_on(branch, np.clip(along, 0.0, 1.0), rig.own_joint, rig.anchor_joints,
                                  rig.anchor_weights, rig.trunk_branch)
    weights = weights.astype(np.float32)
    weights[:, 0] += 1.0 - weights.sum(axis=1)  # float32 sums of exactly 1, as glTF asks
    return joints.astype(np.uint8), weights


def follow_joints(rig: WindRig, points: np.ndarray, branch: np.ndarray) -> np.ndarray:
    """(V,) int64: the one joint each point (a leaf's base) moves with, the heaviest of its skin weights."""
    return skin_weights(rig, points, branch)[0][:, 0].astype(np.int64)


def rotation_vector_quaternions(vectors: np.ndarray) -> np.ndarray:
    """(..., 4) float64 unit quaternions (x, y, z, w) of rotation vectors (..., 3) (axis times angle, radians)."""
    angle = np.linalg.norm(vectors, axis=-1, keepdims=True)
    scale = np.where(angle > 1e-12, np.sin(0.5 * angle) / np.maximum(angle, 1e-12), 0.5)
    return np.concatenate([vectors * scale, np.cos(0.5 * angle)], axis=-1)


def _gust(times: np.ndarray, settings: WindClipSettings, period: float | None) -> np.ndarray:
    rate = GUST_RATE if period is None else loop_rate(GUST_RATE, period)
    return 1.0 - settings.gust + settings.gust * np.sin(rate * times)


def _swing_offsets(level, phase, amplitude, times, settings, period: float | None) -> np.ndarray:
    """(K, n, 3) the shader's branch swing, Z up, for branches of `level`, `phase` (n,) whose swing is
    `amplitude` (n,) metres per unit strength, at `times` (K,)."""
    beat_rate = BEAT_BASE + BEAT_PER_LEVEL * level
    across_rate = ACROSS_BEAT * beat_rate
    if period is not None:
        beat_rate, across_rate = loop_rate(beat_rate, period), loop_rate(across_rate, period)
    start = 2.0 * np.pi * phase
    beat = times[:, None] * beat_rate + start
    across = times[:, None] * across_rate + ACROSS_BEAT * start
    swing = settings.strength * amplitude
    return swing[None, :, None] * (np.sin(beat)[..., None] * (WIND_DIRECTION - DROOP_SHARE * _UP)
                                   + ACROSS_SHARE * np.cos(across)[..., None] * WIND_ACROSS)


def _arc_quaternions(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (x, y, z, w) of the smallest rotations turning vectors a (..., 3) toward b."""
    w = row_norms(a.reshape(-1, 3)).reshape(a.shape[:-1]) * row_norms(b.reshape(-1, 3)).reshape(b.shape[:-1]) \
        + np.einsum("...i,...i->...", a, b)
    q = np.concatenate([np.cross(a, b), w[..., None]], axis=-1)
    return q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-300)


def _quaternion_products(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(..., 4) p q, both (..., 4) quaternions (x, y, z, w)."""
    pv, pw, qv, qw = p[..., :3], p[..., 3:], q[..., :3], q[..., 3:]
    return np.concatenate([pw * qv + qw * pv + np.cross(pv, qv), pw * qw - np.einsum("...i,...i->...", pv, qv)[
        ..., None]], axis=-1)


def wind_clip(rig: WindRig, settings: WindClipSettings) -> WindClip:
    """The looping clip: SAMPLES_PER_SECOND keys a second over `settings.period_s`, each rate of the shader
    rounded to whole cycles. The trunk's joints bend so that its points at the joints sit where the shader's
    quadratic lean puts them; a branch's joint turns the branch so that its tip, seen from its pivot, moves as
    the shader moves it: the lean's difference between tip and pivot plus the branch's own swing (the part across
    the branch: a turn keeps its length). Children inherit their parent's motion, which the shader leaves out."""
    period = float(settings.period_s)
    times = np.linspace(0.0, period, int(np.rint(period * SAMPLES_PER_SECOND)) + 1)
    gust = settings.strength * LEAN_PER_STRENGTH * _gust(times, settings, period)  # (K,) lean per unit height
    height = max(rig.height, 1e-6)
    world = np.zeros((len(times), rig.n_joints, 4))
    trunk = np.arange(TRUNK_SEGMENTS)
    # Chord slope of the lean d(z) = gust H (z / H)^2 over each segment: (z_k + z_k+1) gust / H.
    bottoms = rig.position[trunk, 2]
    tops = np.append(bottoms[1:], bottoms[-1] + rig.reach[TRUNK_SEGMENTS - 1])
    tilt = np.arctan(gust[:, None] * np.minimum(bottoms + tops, 3.0 * height) / height)  # (K, S)
    world[:, trunk] = rotation_vector_quaternions(tilt[..., None] * _LEAN_AXIS)
    branches = np.arange(TRUNK_SEGMENTS, rig.n_joints)
    if len(branches):
        pivot = rig.position[branches]
        arm = rig.direction[branches] * rig.reach[branches, None]
        tip = pivot + arm

        def lean(points):  # (K, n, 3) the shader's lean of points (n, 3)
            h = np.clip(points[:, 2] / height, 0.0, 1.5)
            return gust[:, None, None] * height * (h * h)[None, :, None] * WIND_DIRECTION

        level = rig.level[branches]
        amplitude = np.where(level >= 1, (SWING_BASE + SWING_PER_LEVEL * level) * rig.reach[branches], 0.0)
        moved = arm + lean(tip) - lean(pivot) + _swing_offsets(level, rig.phase[branches], amplitude, times,
                                                               settings, period)
        world[:, branches] = _arc_quaternions(np.broadcast_to(arm, moved.shape), moved)
    parent_world = world[:, np.maximum(rig.parent, 0)]
    parent_world[:, rig.parent < 0] = [0.0, 0.0, 0.0, 1.0]
    inverse = parent_world * np.array([-1.0, -1.0, -1.0, 1.0])
    rotations = _quaternion_products(inverse, world)
    rotations[rotations[..., 3] < 0] *= -1.0  # one sign per rotation: bytes do not hang on the arithmetic's
    rotations /= np.linalg.norm(rotations, axis=-1, keepdims=True)
    rotations[-1] = rotations[0]  # whole cycles: the same to rounding; exactly the same, so the loop is seamless
    impostor = rotation_vector_quaternions(np.arctan(gust)[:, None] * _LEAN_AXIS)
    impostor[-1] = impostor[0]
    return WindClip(times, rotations, impostor)


def _quaternion_matrices(quaternions: np.ndarray) -> np.ndarray:
    x, y, z, w = np.moveaxis(quaternions, -1, 0)
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def joint_world_poses(rig: WindRig, rotations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotation (K, J, 3, 3) and position (K, J, 3) (metres, Z up) of every joint for local rotations
    (K, J, 4); a point p at rest on joint j moves to R_j (p - rest_j) + position_j."""
    local = _quaternion_matrices(rotations)
    world = np.empty_like(local)
    position = np.empty(rotations.shape[:2] + (3,))
    offsets = rig.local_translation
    for j in range(rig.n_joints):  # parents before children; J is at most the joint budget
        p = rig.parent[j]
        if p < 0:
            world[:, j], position[:, j] = local[:, j], offsets[j]
        else:
            world[:, j] = world[:, p] @ local[:, j]
            position[:, j] = position[:, p] + world[:, p] @ offsets[j]
    return world, position


def shader_wind_offset(points: np.ndarray, wind: np.ndarray, pivot: np.ndarray, times: np.ndarray,
                       settings: WindClipSettings, height: float, looped: bool = True) -> np.ndarray:
    """(K, V, 3) the shader's offset (trunk lean plus branch swing, no flutter), Z up, of points (V, 3) with
    their wind data (V, 4) and pivots (V, 3) at `times` (K,): what the clip is made to follow. `looped`: with
    the clip's rounded rates (False: the shader's own)."""
    period = float(settings.period_s) if looped else None
    h = np.clip(points[:, 2] / height, 0.0, 1.5)
    lean = settings.strength * LEAN_PER_STRENGTH * height * _gust(times, settings, period)[:, None] * h * h
    offsets = lean[..., None] * WIND_DIRECTION
    level, along, phase = wind[:, 0], wind[:, 1], wind[:, 2]
    amplitude = np.where(level >= 1, (SWING_BASE + SWING_PER_LEVEL * level) * row_norms(points - pivot) * along,
                         0.0)
    return offsets + _swing_offsets(level, phase, amplitude, times, settings, period)
