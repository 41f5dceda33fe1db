"""Growing one level of Weber-Penn stems in lockstep: curvature, splits, vertical attraction, envelope pruning.

`grow_level(stems, ...)` takes the new stems of a level (`Level.new_stems`) and returns them grown, with the
split-off stems appended; points live in dense (S, curveRes + 1) grids indexed by growth step.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ..geometry import rotations as rot
from ..errors import TreeTooLargeError
from .shapes import shape_ratio

__all__ = ["Level", "grow_level"]

TAU = 2 * np.pi
Z_AXIS = np.array([0.0, 0.0, 1.0])
MAX_STEMS_PER_LEVEL = 100_000  # beyond this a tree no longer fits a farm worker's memory or a GLB reader


@dataclass
class Level:
    """The stems (splines) of one level, arrays over S splines; a split appends a row."""

    seg_max: int
    seg_len: np.ndarray        # (S,) metres per segment
    curv: np.ndarray           # (S,) radians of bend per segment
    rad_s: np.ndarray          # (S,) radius at the stem start
    rad_e: np.ndarray          # (S,) radius at the stem end
    children: np.ndarray       # (S,) child stems (or leaves) this stem's family sprouts
    family: np.ndarray         # (S,) int, the original stem a split descends from
    k_start: np.ndarray        # (S,) int, growth step at which the spline starts
    offset_len: np.ndarray     # (S,) metres of family stem below the spline start
    collar: np.ndarray         # (S,) bool, stem sprouted from a parent (owns a collar node)
    parent_spline: np.ndarray  # (S,) int, global id of the parent spline (-1: trunk or a split, see parent_row)
    parent_row: np.ndarray     # (S,) int, row of the spline a split came from (-1 otherwise)
    parent_u: np.ndarray       # (S,) position of the start on the parent spline, in steps
    attach_points: np.ndarray  # (S, 3) where a sprouted stem leaves its parent's axis
    attach_radii: np.ndarray   # (S,) parent radius there
    collar_points: np.ndarray  # (S, 3) the sprouted stem's own first node, at the parent's surface
    points: np.ndarray         # (S, K + 1, 3) positions by growth step
    radii: np.ndarray          # (S, K + 1)
    valid: np.ndarray          # (S, K + 1) bool
    spline_id: np.ndarray      # (S,) int, global spline id (set after growth)

    @classmethod
    def new_stems(cls, co, direction, seg_len, curv, rad_s, rad_e, children, first_radius, parent_spline,
                  parent_u, collar: bool, seg_max: int, parent_radius=None) -> "Level":
        s = len(co)
        k = seg_max
        direction = direction / np.linalg.norm(direction, axis=1, keepdims=True)
        points = np.zeros((s, k + 1, 3))
        radii = np.zeros((s, k + 1))
        valid = np.zeros((s, k + 1), bool)
        points[:, 0], radii[:, 0], valid[:, 0] = co, first_radius, True
        par_r = np.zeros(s) if parent_radius is None else np.asarray(parent_radius, np.float64)
        collar_points = co + direction * np.minimum(par_r, 0.5 * seg_len)[:, None]
        level = cls(seg_max=k, seg_len=seg_len.astype(np.float64), curv=curv.astype(np.float64),
                    rad_s=rad_s.astype(np.float64), rad_e=rad_e.astype(np.float64),
                    children=children.astype(np.float64), family=np.arange(s), k_start=np.zeros(s, np.int64),
                    offset_len=np.zeros(s), collar=np.full(s, collar), parent_spline=np.asarray(parent_spline),
                    parent_row=np.full(s, -1), parent_u=np.asarray(parent_u, np.float64),
                    attach_points=np.asarray(co, np.float64), attach_radii=par_r, collar_points=collar_points,
                    points=points, radii=radii, valid=valid, spline_id=np.arange(s))
        level._start_dir = direction
        return level

    @property
    def n_splines(self) -> int:
        return len(self.seg_len)

    @property
    def n_points(self) -> np.ndarray:
        return self.valid.sum(axis=1)

    @property
    def rows(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "seg_max"}

    @property
    def children_of_family(self) -> np.ndarray:
        out = np.zeros(int(self.family.max()) + 1)
        roots = self.family == np.arange(self.n_splines)
        out[self.family[roots]] = self.children[roots]
        return out


def _append(level: Level, new: dict) -> Level:
    merged = {k: np.concatenate([v, new[k]]) for k, v in level.rows.items()}
    out = Level(seg_max=level.seg_max, **merged)
    out._start_dir = getattr(level, "_start_dir", None)
    return out


def _up_curve(v: np.ndarray, attract: float, seg_max: int) -> np.ndarray:
    """Sapling's vertical attraction: turn each unit direction toward (or, if negative, away from) world up.

    Sapling turns about the tracking frame's x axis, by attractUp * declination * |frame y . up| / curveRes;
    that frame's y is world up projected off the direction, so the turn is in the vertical plane.
    """
    if attract == 0:
        return v
    dz = np.clip(v[:, 2], -1.0, 1.0)
    sin_dec = np.sqrt(1.0 - dz * dz)
    dec = np.arccos(dz)
    angle = attract * dec * sin_dec / seg_max
    angle = np.where(-dec + angle < -np.pi, -np.pi + dec, angle)
    angle = np.where(dec - angle < 0, dec, angle)
    up = -dz[:, None] * v
    up[:, 2] += 1.0
    up /= np.where(sin_dec > 1e-12, sin_dec, 1.0)[:, None]
    return np.cos(angle)[:, None] * v + np.sin(angle)[:, None] * up


def _bent(bend: np.ndarray, across: np.ndarray) -> np.ndarray:
    """(N, 3) = Ry(across) @ Rx(bend) @ z: a stem's next direction in its own frame."""
    cb = np.cos(bend)
    return np.stack([cb * np.sin(across), -np.sin(bend), cb * np.cos(across)], axis=1)


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-300)


def _grow_once(stems: Level, p, draws, n, scale_val, close_tip, scale, rng) -> Level:
    """Grow every stem of the level through all its segments; `scale` (S,) scales segment lengths."""
    k_max = stems.seg_max
    lv = p["lengthV"][n]
    level = replace(stems, **{k: v.copy() for k, v in stems.rows.items()})
    level._start_dir = stems._start_dir
    family_seg = stems.seg_len * scale  # Sapling's stemsegL: the family's length before variation
    level.seg_len = family_seg * (rng.uniform(1 - lv, 1 + lv, len(family_seg)) if lv else 1.0)
    s = level.n_splines
    pos = level.points[:, 0].copy()
    direction = level._start_dir.copy()
    sign = np.ones(s)
    split_last = np.zeros(s, np.int64)
    r_last = np.full(s, np.nan)
    seg_family = family_seg.copy()
    cv1 = draws["curveV1"][n] / k_max
    cv2 = draws["curveV2"][n] / k_max
    split_angle = np.radians(p["splitAngle"][n])
    angle_base = draws["sign1"] * (split_angle + draws["splitAngleV1"][n])
    spread = draws["sign2"] * (split_angle + draws["splitAngleV2"][n])
    branch_turn = np.radians(p["rotate"][0] + p["rotateV"][0])
    length_prod = float(np.prod(p["length"][: n + 1]))
    for k in range(k_max):
        kp = k / (k_max - 1) if k_max > 1 else 1.0
        split_value = p["segSplits"][n]
        if n == 0:
            split_value = max(((2 * p["splitBias"]) * (kp - 0.5) + 1) * split_value, 0.0)
        split_val = np.where(split_last == 0, split_value * 1.33, split_value * split_value)
        n_split = _split_counts(k, k_max, n, p, split_val, level.seg_len, scale_val, length_prod, draws, rng)
        if k == int(k_max / 2 + 0.5) and p["curveBack"][n] != 0:
            level.curv += 2 * np.radians(p["curveBack"][n]) / k_max
        s_curv = level.curv if not (n == 0 and kp <= p["splitHeight"]) else np.zeros(s)
        bend = s_curv + cv1 * kp * sign
        bend_across = cv2 * kp * sign
        sign = -sign
        frames = rot.tilt_frames(direction) if n == 0 else rot.track_frames(direction)
        if n == 0:
            dec = np.degrees(rot.declination(direction)) / 180
            tf = np.maximum(0.1, 1 - dec ** 2 * p["taperCrown"] * 30)
        else:
            tf = np.ones(s)
        out_att = p["attractOut"][n]
        if n > 0 and kp > 0 and out_att > 0:
            azimuth = np.arctan2(pos[:, 0], -pos[:, 1]) + TAU
            euler = rot.euler_xyz(frames, azimuth)
            fac = kp * out_att
            x = np.sin(euler[:, 2]) + (np.sin(azimuth) - np.sin(euler[:, 2])) * fac
            y = np.cos(euler[:, 2]) + (np.cos(azimuth) - np.cos(euler[:, 2])) * fac
            euler[:, 2] = np.arctan2(x, y)
            frames = rot.from_euler_xyz(euler)
        splitting = n_split > 0
        turn = np.zeros(s)
        angle = np.zeros(s)
        if splitting.any():
            angle[splitting] = angle_base
            if n > 0:
                dec_deg = np.degrees(rot.declination(frames[splitting][:, :, 2]))
                angle[splitting] *= np.maximum(1 - dec_deg / 90, 0) * 0.67 + 0.33
            fresh = splitting & np.isnan(r_last)
            r_last[fresh] = draws["rLastAng"][n]
            turn[splitting] = r_last[splitting] + branch_turn
            r_last[splitting] = turn[splitting]
        # The continuing stem of every spline (turn and spread are 0 where it does not split).
        local = _bent(np.where(splitting, -angle, 0.0) + bend, np.broadcast_to(bend_across, (s,)))
        if n == 0:
            local = rot.premul("z", turn, local)
        else:
            local = rot.premul("y", -np.where(splitting, spread, 0.0), local)
        grow_dir = _unit(_up_curve(rot.apply(frames, local), p["attractUp"][n], k_max))
        new_pos = pos + grow_dir * (level.seg_len * tf)[:, None]
        radius = level.rad_s * (1 - (k + 1) / k_max) + level.rad_e * ((k + 1) / k_max)
        if close_tip and k == k_max - 1:
            radius = np.zeros(s)
        level.points[:, k + 1], level.radii[:, k + 1], level.valid[:, k + 1] = new_pos, radius, True
        clones = None
        if splitting.any():
            clones = _clones(level, np.flatnonzero(splitting), n_split, k, n, frames, bend, bend_across, angle,
                             spread, turn, tf, seg_family, pos, p, rng)
        pos, direction = new_pos, grow_dir
        split_last = splitting.astype(np.int64)
        if clones is not None:
            new_rows, clone_dir = clones
            level = _append(level, new_rows)
            pos = np.concatenate([pos, new_rows["points"][:, k + 1]])
            direction = np.concatenate([direction, clone_dir])
            sign = np.concatenate([sign, np.ones(len(clone_dir))])
            split_last = np.concatenate([split_last, np.ones(len(clone_dir), np.int64)])
            r_last = np.concatenate([r_last, new_rows.pop("_r_last")])
            seg_family = np.concatenate([seg_family, new_rows.pop("_seg_family")])
            s = level.n_splines
            if s > MAX_STEMS_PER_LEVEL:
                raise TreeTooLargeError(
                    f"level {n} grew {s} stems (limit {MAX_STEMS_PER_LEVEL}): segSplits[{n}] = "
                    f"{p['segSplits'][n]} and curveRes[{n}] = {k_max} split too often; lower them")
    return level


def _split_counts(k, k_max, n, p, split_val, seg_len, scale_val, length_prod, draws, rng) -> np.ndarray:
    s = len(split_val)
    if k == 0:
        return np.zeros(s, np.int64)
    if n == 0 and k < (k_max - 1) * p["splitHeight"] and k != 1:
        return np.zeros(s, np.int64)
    if k == 1 and n == 0:
        return np.full(s, p["baseSplits"], np.int64)
    forced = n == 0 and k == int((k_max - 1) * p["splitHeight"]) + 1
    prob = split_val
    if n >= 1 and p["splitByLen"]:
        prob = split_val * (seg_len * k_max / scale_val) / length_prod
    draw = draws["rSplits2"] if draws["rSplits2"] is not None else rng.random(s)
    count = (draw < prob).astype(np.int64)
    if forced:
        count = np.where(split_val > 0, 1, count)
    return count


def _clones(level, rows, n_split, k, n, frames, bend, bend_across, angle, spread, turn, tf, seg_family, pos,
            p, rng):
    """New splines split off at step k (Sapling's growSpline with numSplit > 0)."""
    m = n_split[rows]
    parent = np.repeat(rows, m)
    i = np.arange(len(parent)) - np.repeat(np.cumsum(m) - m, m)
    lv = p["lengthV"][n]
    len_var = rng.uniform(1 - lv, 1 + lv, len(parent)) if lv else np.ones(len(parent))
    b_scale = np.minimum(len_var * tf[parent], 1.0)
    local = _bent(angle[parent] + bend[parent], np.broadcast_to(bend_across, bend.shape)[parent])
    if n == 0:
        around = np.pi - (TAU / (m[np.searchsorted(rows, parent)] + 1)) * (i + 1)
        local = rot.premul("z", around + turn[parent], local)
    else:
        local = rot.premul("y", np.full(len(parent), spread), local)
    v = _unit(_up_curve(rot.apply(frames[parent], local), p["attractUp"][n], level.seg_max))
    seg_len = seg_family[parent] * len_var
    end = pos[parent] + v * (seg_len * tf[parent])[:, None]
    k_max = level.seg_max
    r_now = (level.rad_s[parent] * (1 - k / k_max) + level.rad_e[parent] * (k / k_max)) * b_scale
    r_next = (level.rad_s[parent] * (1 - (k + 1) / k_max) + level.rad_e[parent] * ((k + 1) / k_max)) * b_scale
    c = len(parent)
    points = np.zeros((c, k_max + 1, 3))
    radii = np.zeros((c, k_max + 1))
    valid = np.zeros((c, k_max + 1), bool)
    points[:, k], points[:, k + 1] = pos[parent], end
    radii[:, k], radii[:, k + 1] = r_now, r_next
    valid[:, k], valid[:, k + 1] = True, True
    n_points_before = level.valid[parent].sum(axis=1) - 1  # the step's new point is already in place
    new = {
        "seg_len": seg_len, "curv": level.curv[parent], "rad_s": level.rad_s[parent] * b_scale,
        "rad_e": level.rad_e[parent] * b_scale, "children": level.children[parent],
        "family": level.family[parent], "k_start": np.full(c, k, np.int64),
        "offset_len": level.offset_len[parent] + level.seg_len[parent] * (n_points_before - 1),
        "collar": np.zeros(c, bool), "parent_spline": np.full(c, -1), "parent_row": parent,
        "parent_u": np.full(c, float(k)), "attach_points": pos[parent], "attach_radii": r_now,
        "collar_points": pos[parent], "points": points, "radii": radii, "valid": valid,
        "spline_id": np.arange(level.n_splines, level.n_splines + c),
        "_r_last": turn[parent] + np.pi, "_seg_family": seg_family[parent],
    }
    return new, v


def _inside_envelope(level: Level, p, n, scale_val, prune_base) -> np.ndarray:
    """(S,) whether each spline's end lies inside Sapling's pruning envelope."""
    ends = level.points[np.arange(level.n_splines), level.k_start + level.n_points - 1]
    reach = np.hypot(ends[:, 0], ends[:, 1])
    ratio = (scale_val - ends[:, 2]) / (scale_val * max(1 - prune_base, 1e-6))
    width = p["pruneWidth"] * shape_ratio(9, ratio, None, p["pruneWidthPeak"], p["prunePowerHigh"],
                                          p["prunePowerLow"])
    inside = reach / scale_val < width
    if n == 0:
        inside |= ends[:, 2] < prune_base * scale_val
    return inside


def grow_level(stems: Level, p, draws, n, scale_val, base_size, close_tip, rng, first_id: int = 0) -> Level:
    """Grow a level; with `prune`, bisect each family's length scale until its tips fit the envelope."""
    level_seed = int(rng.integers(0, 2**63 - 1))
    n_fam = stems.n_splines
    scale = np.ones(n_fam)
    if p["prune"]:
        prune_base = min(p["pruneBase"], p["baseSize"])
        lo, hi, old_hi = np.zeros(n_fam), np.ones(n_fam), np.ones(n_fam)
        active = np.ones(n_fam, bool)
        for _ in range(40):
            if not active.any():
                break
            finishing = active & (hi - lo < 0.01)
            scale = np.where(finishing, (scale - 1) * p["pruneRatio"] + 1, scale)
            trial = _grow_once(stems, p, draws, n, scale_val, close_tip, scale, np.random.default_rng(level_seed))
            inside_spline = _inside_envelope(trial, p, n, scale_val, prune_base)
            inside = np.ones(n_fam, bool)
            np.logical_and.at(inside, trial.family, inside_spline)
            search = active & ~finishing
            shrink = search & ~inside
            old_hi = np.where(shrink, hi, old_hi)
            hi = np.where(shrink, scale, hi)
            grow_back = search & inside & (scale != 1)
            lo = np.where(grow_back, scale, lo)
            hi = np.where(grow_back, old_hi, hi)
            lo = np.where(search & inside & (hi - lo == 1), 1.0, lo)
            scale = np.where(shrink | grow_back, 0.5 * (hi + lo), scale)
            active = search & (hi - lo > 0.005)
    level = _grow_once(stems, p, draws, n, scale_val, close_tip, scale, np.random.default_rng(level_seed))
    rows = level.parent_row >= 0
    level.spline_id = np.arange(level.n_splines) + first_id
    level.parent_spline = np.where(rows, level.spline_id[np.maximum(level.parent_row, 0)], level.parent_spline)
    level.collar_points = np.where(level.collar[:, None], level.collar_points, level.points[:, 0])
    return level
