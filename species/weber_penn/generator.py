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

from dataclasses import dataclass

import numpy as np

from ..geometry import rotations as rot
from ..skeleton import Skeleton
from .leaves import leaf_transforms
from .schema import validate
from .shapes import auto_taper, shape_ratio
from .stems import Level, grow_level

__all__ = ["grow", "grow_validated", "WeberPennTree"]

TAU = 2 * np.pi
MIN_RADIUS = 1e-4  # metres; Sapling allows 0 at tips, a skeleton needs > 0


@dataclass
class ChildPoints:
    """Where the stems of the next level (or the leaves) sprout, arrays over P points."""

    co: np.ndarray          # (P, 3) position
    tangent: np.ndarray     # (P, 3) unit direction of the parent stem there
    rad_par: np.ndarray     # (P,) start radius of the parent stem
    radius: np.ndarray      # (P,) parent radius at the point
    offset: np.ndarray      # (P,) t along the parent family (1 = a stem tip)
    stem_offset: np.ndarray  # (P,) offset rescaled above the base size
    length_par: np.ndarray  # (P,) length of the parent stem
    spline: np.ndarray      # (P,) int, parent spline id
    u: np.ndarray           # (P,) position on the parent spline in segment steps

    def take(self, index: np.ndarray) -> "ChildPoints":
        return ChildPoints(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    def __len__(self) -> int:
        return len(self.offset)


@dataclass
class WeberPennTree:
    """The grown tree before assembly: all stem points of all levels plus leaf transforms."""

    levels: list
    leaves: np.ndarray
    leaf_spline: np.ndarray
    leaf_u: np.ndarray


def grow(params: dict, rng: np.random.Generator) -> Skeleton:
    """Grow a Weber-Penn tree from a Sapling dictionary; see the module docstring for the realized draws."""
    return grow_validated(validate(params), rng)


def grow_validated(p: dict, rng: np.random.Generator) -> Skeleton:
    levels = p["levels"]
    deg = np.radians
    draws = _realized_draws(p, rng)
    scale_val = p["scale"] + draws["scaleV"]
    scale_val += np.copysign(1e-6, scale_val)
    taper = auto_taper(p["length"], p["taper"], p["shape"], p["shapeS"], levels, p["customShape"]) \
        if p["autoTaper"] else list(p["taper"])
    leaves = p["leaves"]
    base_size = p["baseSize"]
    grown_levels = []
    child = None
    next_id = 0
    for n_store in range(levels):
        n = min(3, n_store)
        last = n_store == levels - 1
        if n == 0:
            stems = _trunk(p, draws, scale_val, taper, leaves)
        else:
            stems = _fabricate(p, draws, child, n, n_store, scale_val, base_size, taper, rng)
            base_size *= p["baseSize_s"]
        if last:
            base_size = 0.0
        if stems is None:
            break
        level = grow_level(stems, p, draws, n, scale_val, base_size, last and p["closeTip"], rng, next_id)
        next_id += level.n_splines
        grown_levels.append(level)
        child = _child_points(level, p, n, base_size, rng)
    leaf_mats, leaf_spline, leaf_u = (np.zeros((0, 4, 4)), np.zeros(0, np.int64), np.zeros(0))
    if leaves and child is not None and len(child):
        leaf_mats, pick = leaf_transforms(child, p, draws, rng)
        leaf_spline, leaf_u = child.spline[pick], child.u[pick]
    return _assemble(WeberPennTree(grown_levels, leaf_mats, leaf_spline, leaf_u))


# ---------------------------------------------------------------------------------------------- draws
def _realized_draws(p: dict, rng: np.random.Generator) -> dict:
    """TreeSketchNet's stored draws, or fresh ones from rng where the dictionary lacks them."""
    out = {}
    out["scaleV"] = p.get("scaleV", 0.0)
    out["scaleV0"] = p["scaleV0"] if "scaleV0" in p else 1.0
    out["leafScaleV"] = p["leafScaleV"] if "leafScaleV" in p else 1.0
    out["curveV1"] = np.radians(p["curveV1"]) if "curveV1" in p else np.zeros(4)
    out["curveV2"] = np.radians(p["curveV2"]) if "curveV2" in p else np.zeros(4)
    out["splitAngleV1"] = np.radians(p["splitAngleV1"]) if "splitAngleV1" in p else np.zeros(4)
    out["splitAngleV2"] = np.radians(p["splitAngleV2"]) if "splitAngleV2" in p else np.zeros(4)
    out["rLastAng"] = np.radians(p["rLastAng"]) if "rLastAng" in p else rng.uniform(0, TAU, 4)
    out["sign1"] = 1.0 if p.get("choiceNegPos1", 1) > 0 else -1.0
    out["sign2"] = 1.0 if p.get("choiceNegPos2", 1) > 0 else -1.0
    out["rSplits2"] = p.get("rSplits2")  # None: draw per decision
    return out


# ---------------------------------------------------------------------------------------------- trunk
def _trunk(p, draws, scale_val, taper, leaves) -> Level:
    length = scale_val * p["length"][0]
    res = p["curveRes"][0]
    children = leaves if p["levels"] == 1 else p["branches"][1]
    start = scale_val * p["ratio"] * p["scale0"] * draws["scaleV0"]
    end = max((start * (1 - taper[0])) ** p["ratioPower"], p["minRadius"])
    start = max(start, p["minRadius"])
    return Level.new_stems(
        co=np.zeros((1, 3)), direction=np.array([[0.0, 0.0, 1.0]]), seg_len=np.array([length / res]),
        curv=np.array([np.radians(p["curve"][0]) / res]), rad_s=np.array([start]), rad_e=np.array([end]),
        children=np.array([float(children)]), first_radius=np.array([start * p["rootFlare"]]),
        parent_spline=np.array([-1]), parent_u=np.array([0.0]), collar=False, seg_max=res)


# ---------------------------------------------------------------------------------------------- branches
def _fabricate(p, draws, cp: ChildPoints, n, n_store, scale_val, base_size, taper, rng) -> Level | None:
    """Start the stems of level n at the child points of level n - 1 (Sapling's fabricate_stems)."""
    base_size = min(0.999, base_size)
    rotate, rotate_v = np.radians(p["rotate"][n]), np.radians(p["rotateV"][n])
    down, down_v = np.radians(p["downAngle"][n]), np.radians(p["downAngleV"][n])
    rot_a = None
    if n == 1 and p["rMode"] != "original" and len(cp):
        cp, rot_a = _pick_trunk_points(cp, p, base_size, rng)
    count = len(cp)
    if count == 0:
        return None
    at_tip = cp.offset == 1
    rel = (1 - cp.offset) / (1 - base_size)
    if p["useOldDownAngle"]:
        down_var = (down_v * (1 - 2 * (0.2 + 0.8 * rel)) if down_v < 0
                    else rng.uniform(-down_v, down_v, count) if down_v else np.zeros(count))
    else:
        down_var = (rng.uniform(down_v, -down_v, count) if down_v < 0 else -down_v * (1 - rel) ** 2)
    down_angle = np.where(at_tip, 0.0, down + down_var)
    if rotate < 0:
        old = -abs(rotate) * np.where(np.arange(count) % 2 == 0, 1.0, -1.0)
    else:
        old = rotate * np.arange(1, count + 1)
    b_rotate = old + (rng.uniform(-abs(rotate_v), abs(rotate_v), count) if rotate_v else 0.0)
    if rot_a is not None:
        b_rotate = rot_a
    local = rot.apply(rot.rot_z(b_rotate) @ rot.rot_x(down_angle), np.tile([0.0, 0.0, 1.0], (count, 1)))
    frames = rot.track_frames(cp.tangent)
    if n == 1 and p["rMode"] == "rotate":
        world = local.copy()
        tilt = ~at_tip
        if p["useParentAngle"] and tilt.any():
            ez = rot.euler_xyz(frames[tilt], b_rotate[tilt])[:, 2]
            dec = rot.declination(cp.tangent[tilt])
            tilt_m = rot.rot_z(ez) @ rot.rot_x(dec) @ rot.rot_z(-ez)
            world[tilt] = rot.apply(tilt_m, local[tilt])
        world[at_tip] = rot.apply(frames[at_tip], local[at_tip])
    else:
        world = rot.apply(frames, local)

    lengths = np.asarray(p["length"], np.float64)
    max_len = scale_val * np.prod(lengths[: n + 1])
    ratio = (1 - cp.stem_offset) / (1 - base_size)
    shape = shape_ratio(p["shape"], ratio, p["customShape"]) if n == 1 else shape_ratio(p["shapeS"], ratio)
    branch_len = cp.length_par * lengths[n] * shape
    children = p["branches"][min(3, n + 1)] * (0.1 + 0.9 * branch_len / max_len)
    if n_store == p["levels"] - 1:
        leaves = p["leaves"]
        children = (np.zeros(count) if leaves < 0 else
                    leaves * (0.1 + 0.9 * branch_len / max_len) * shape_ratio(p["leafDist"], 1 - cp.offset))
    with np.errstate(divide="ignore", invalid="ignore"):
        start = np.minimum(cp.rad_par * (branch_len / cp.length_par) ** p["ratioPower"] * p["radiusTweak"][n],
                           cp.radius)
    start = np.where(at_tip, cp.radius, start)
    end = np.maximum((start * (1 - taper[n])) ** p["ratioPower"], p["minRadius"])
    start = np.maximum(start, p["minRadius"])
    res = p["curveRes"][n]
    keep = branch_len > 1e-5 * scale_val  # a zero-length stem has no geometry
    if not keep.any():
        return None
    k = np.flatnonzero(keep)
    return Level.new_stems(
        co=cp.co[k], direction=world[k], seg_len=branch_len[k] / res,
        curv=np.full(len(k), np.radians(p["curve"][n]) / res), rad_s=start[k], rad_e=end[k],
        children=children[k], first_radius=start[k], parent_spline=cp.spline[k], parent_u=cp.u[k],
        collar=True, seg_max=res, parent_radius=cp.radius[k])


def _pick_trunk_points(cp: ChildPoints, p, base_size, rng):
    """Sapling's 'rotate' mode for first-level branches: one sprout per height, turned to a rotation angle."""
    tips = np.flatnonzero(cp.offset == 1)
    inner = np.flatnonzero(cp.offset != 1)
    if len(inner) == 0:
        return cp.take(tips), np.zeros(len(tips))
    keys, group = np.unique(cp.offset[inner], return_inverse=True)
    n_groups = len(keys)
    rotate, rotate_v = np.radians(p["rotate"][1]), np.radians(p["rotateV"][1])
    if rotate < 0:
        old = -abs(rotate) * np.where(np.arange(n_groups) % 2 == 0, 1.0, -1.0)
    else:
        old = rotate * np.arange(1, n_groups + 1)
    b_rotate = old + (rng.uniform(-abs(rotate_v), abs(rotate_v), n_groups) if rotate_v else 0.0)
    co = cp.co[inner]
    if p["rMode"] == "rotate":
        a1 = np.mod(b_rotate, TAU)[group]
        a2 = np.arctan2(co[:, 0], -co[:, 1])
        diff = np.minimum(np.mod(a1 - a2 + TAU, TAU), np.mod(a2 - a1 + TAU, TAU))
        order = np.lexsort((np.arange(len(inner)), diff, group))
        first = np.ones(len(order), bool)
        first[1:] = group[order][1:] != group[order][:-1]
        chosen = order[first]  # one per group, groups ascending
    else:  # random
        counts = np.bincount(group, minlength=n_groups)
        starts = np.concatenate(([0], np.cumsum(counts)[:-1]))
        by_group = np.argsort(group, kind="stable")
        chosen = by_group[starts + rng.integers(0, counts)]
    pick = inner[chosen]
    sel = cp.take(pick)
    rot_a = np.zeros(len(pick))
    if p["rMode"] == "rotate":
        b = sel.co
        reach = np.hypot(b[:, 0], b[:, 1])
        ratio = (1 - sel.offset) / (1 - base_size)
        bl = sel.length_par * p["length"][1] * shape_ratio(p["shape"], ratio, p["customShape"])
        down = np.radians(p["downAngle"][1])
        if p["downAngleV"][1] > 0:
            down = down - np.radians(p["downAngleV"][1]) * (1 - ratio) ** 2
        down = np.broadcast_to(down, bl.shape)
        bl = np.where(down < 0.5 * np.pi, bl * np.sin(down) ** 2, bl) * 0.33
        target = np.stack([np.sin(b_rotate), np.cos(b_rotate)], axis=1) * (reach + bl)[:, None]
        rot_a = np.arctan2(target[:, 0] - b[:, 0], target[:, 1] + b[:, 1])
    return cp.take(np.concatenate([pick, tips])), np.concatenate([rot_a, np.zeros(len(tips))])


# ---------------------------------------------------------------------------------------------- child points
def _child_points(level: Level, p, n, base_size, rng) -> ChildPoints:
    """Points along each stem family where the next level sprouts (Sapling's findChildPoints + interpStem)."""
    fam = level.family
    n_fam = int(fam.max()) + 1
    children = level.children_of_family
    n_points = level.n_points
    n_splines = np.bincount(fam, minlength=n_fam)
    seg_total = np.bincount(fam, weights=n_points - 1, minlength=n_fam)
    if n == 0 and p["rMode"] != "original":
        count = np.floor(children).astype(np.int64)
        denom = children
    else:
        with np.errstate(divide="ignore", invalid="ignore"):
            per_seg = np.where(seg_total > 0, children / seg_total, 0.0)
        denom = np.round(per_seg * level.seg_max)
        count = denom.astype(np.int64)
    none = children <= 0
    count = np.where(none, 1, count)
    denom = np.where(none, 1.0, denom)
    # Flat list of t values per family: t = (a + 1) / denom, a < count.
    fam_of_t = np.repeat(np.arange(n_fam), count)
    a = np.arange(len(fam_of_t)) - np.repeat(np.cumsum(count) - count, count)
    t = (a + 1) / denom[fam_of_t]
    trim = np.floor(base_size * (count + 1)).astype(np.int64)
    keep = a >= trim[fam_of_t]
    fam_of_t, t, a = fam_of_t[keep], t[keep], a[keep]
    if n == 0 and p["nrings"] > 0:
        not_last = a < (count - 1)[fam_of_t]
        rings = p["nrings"]
        jitter = rng.uniform(0.995, 1.005, len(t))
        t = np.where(not_last, np.floor(t * rings) / rings * jitter, 1.0)
        keep = t > base_size
        fam_of_t, t = fam_of_t[keep], t[keep]
    if n == 0:
        bs = base_size
        x = (t - bs) / (1 - bs)
        dist = p["branchDist"]
        x = np.power(np.clip(x, 0, None), 1 / dist) if dist < 1.0 else 1 - np.power(np.clip(1 - x, 0, None), dist)
        t = x * (1 - bs) + bs
    # Pair every spline with its family's t values and keep those inside the spline's stretch.
    length = (n_points - 1) * level.seg_len
    fam_max = np.zeros(n_fam)
    np.maximum.at(fam_max, fam, level.offset_len + length)
    bottom = level.offset_len / fam_max[fam]
    top = bottom + length / fam_max[fam]
    t_order = np.argsort(fam_of_t, kind="stable")
    fam_of_t, t = fam_of_t[t_order], t[t_order]
    t_count = np.bincount(fam_of_t, minlength=n_fam)
    t_start = np.cumsum(t_count) - t_count
    reps = t_count[fam]
    spl = np.repeat(np.arange(len(fam)), reps)
    idx = np.repeat(t_start[fam], reps) + (np.arange(reps.sum()) - np.repeat(np.cumsum(reps) - reps, reps))
    tt = t[idx]
    inside = (tt >= bottom[spl]) & (tt <= top[spl]) & (tt < 1.0)
    spl, tt = spl[inside], tt[inside]
    scaled = (tt - bottom[spl]) / np.maximum(top[spl] - bottom[spl], 1e-12)
    with np.errstate(divide="ignore", invalid="ignore"):
        stem_off = (tt - base_size) / (top[spl] - base_size) * (1 - base_size) + base_size
    segs = n_points[spl] - 1
    pos = segs * scaled
    index = np.minimum(np.floor(pos).astype(np.int64), segs - 1)
    frac = pos - index
    k0 = level.k_start[spl] + index
    a_pt, b_pt = level.points[spl, k0], level.points[spl, k0 + 1]
    co = a_pt + frac[:, None] * (b_pt - a_pt)
    tangent = _unit(b_pt - a_pt)
    radius = level.radii[spl, k0] * (1 - frac) + level.radii[spl, k0 + 1] * frac
    # Every spline also sprouts at its tip.
    tips = np.arange(len(fam))
    k_end = level.k_start + n_points - 1
    tip_dir = _unit(level.points[tips, k_end] - level.points[tips, k_end - 1])
    length_par = level.seg_max * level.seg_len
    return ChildPoints(
        co=np.concatenate([co, level.points[tips, k_end]]),
        tangent=np.concatenate([tangent, tip_dir]),
        rad_par=np.concatenate([level.rad_s[spl], level.rad_s]),
        radius=np.concatenate([radius, level.radii[tips, k_end]]),
        offset=np.concatenate([tt, np.ones(len(tips))]),
        stem_offset=np.concatenate([stem_off, np.ones(len(tips))]),
        length_par=np.concatenate([length_par[spl], length_par]),
        spline=np.concatenate([level.spline_id[spl], level.spline_id]),
        u=np.concatenate([k0 + frac, k_end.astype(np.float64)]),
    )


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


# ---------------------------------------------------------------------------------------------- assembly
def _assemble(tree: WeberPennTree) -> Skeleton:
    """Turn stem point grids into one Skeleton: nodes sorted by (spline, position), parents before children."""
    spl_parts, u_parts, pos_parts, rad_parts, order_parts = [], [], [], [], []
    alias_key, alias_target = [], []  # a split's first point is its parent's node
    jn_spline, jn_u, jn_self = [], [], []
    attach_spline, attach_u, attach_pos, attach_rad = [], [], [], []
    for n, level in enumerate(tree.levels):
        valid = level.valid
        s_idx, k_idx = np.nonzero(valid)
        own = k_idx > level.k_start[s_idx]
        first_own = k_idx == level.k_start[s_idx]
        # Fabricated stems own their first point (the collar); splits and the trunk are handled below.
        keep = own | (first_own & (level.collar[s_idx] | (level.parent_spline[s_idx] < 0)))
        s_k, k_k = s_idx[keep], k_idx[keep]
        pts = level.points[s_k, k_k]
        rads = level.radii[s_k, k_k]
        collar_pt = level.collar[s_k] & (k_k == level.k_start[s_k])
        pts[collar_pt] = level.collar_points[s_k[collar_pt]]
        spl_parts.append(level.spline_id[s_k])
        u_parts.append(k_k.astype(np.float64))
        pos_parts.append(pts)
        rad_parts.append(rads)
        order_parts.append(np.full(len(s_k), n))
        split = (~level.collar) & (level.parent_spline >= 0)
        alias_key.append(np.stack([level.spline_id[split], level.k_start[split].astype(np.float64)], axis=1))
        alias_target.append(np.stack([level.parent_spline[split], level.parent_u[split]], axis=1))
        jn_spline.append(level.spline_id)
        jn_u.append(level.parent_u)
        jn_self.append(level.parent_spline)
        fab = level.collar
        attach_spline.append(level.parent_spline[fab])
        attach_u.append(level.parent_u[fab])
        attach_pos.append(level.attach_points[fab])
        attach_rad.append(level.attach_radii[fab])
    # Attachment points of fabricated stems become nodes of their parent stems.
    spline = np.concatenate(spl_parts + attach_spline)
    u = np.concatenate(u_parts + attach_u)
    pos = np.concatenate(pos_parts + attach_pos)
    rad = np.concatenate(rad_parts + attach_rad)
    order_of_spline = np.zeros(int(max(np.max(s) for s in spl_parts)) + 1, np.int64)
    for n, s in enumerate(spl_parts):
        order_of_spline[s] = n
    key = spline * 256.0 + u
    uniq, first = np.unique(key, return_index=True)  # sorted by (spline, u); duplicates keep the first
    spline, u, pos, rad = spline[first], u[first], pos[first], rad[first]
    n_nodes = len(uniq)

    def lookup(s, uu):
        k = np.asarray(s, np.float64) * 256.0 + np.asarray(uu, np.float64)
        i = np.searchsorted(uniq, k)
        i = np.minimum(i, n_nodes - 1)
        found = np.isclose(uniq[i], k, rtol=0, atol=1e-9)
        return np.where(found, i, -1)

    # Resolve aliases (a split's start point -> the node on its parent spline) to node ids.
    a_key = np.concatenate(alias_key) if alias_key else np.zeros((0, 2))
    a_tgt = np.concatenate(alias_target) if alias_target else np.zeros((0, 2))
    alias_node = lookup(a_tgt[:, 0], a_tgt[:, 1]) if len(a_tgt) else np.zeros(0, np.int64)
    alias_keys = a_key[:, 0] * 256.0 + a_key[:, 1]
    alias_sort = np.argsort(alias_keys)
    alias_keys, alias_node = alias_keys[alias_sort], alias_node[alias_sort]

    def lookup_with_alias(s, uu):
        i = lookup(s, uu)
        miss = i < 0
        if miss.any():
            k = np.asarray(s, np.float64)[miss] * 256.0 + np.asarray(uu, np.float64)[miss]
            j = np.clip(np.searchsorted(alias_keys, k), 0, max(len(alias_keys) - 1, 0))
            i[miss] = alias_node[j] if len(alias_keys) else -1
        return i

    parent = np.arange(-1, n_nodes - 1, dtype=np.int64)
    starts = np.ones(n_nodes, bool)
    starts[1:] = spline[1:] != spline[:-1]
    jn_s = np.concatenate(jn_spline)
    jn_parent_spline = np.concatenate(jn_self)
    jn_parent_u = np.concatenate(jn_u)
    parent_spline_of = np.full(int(jn_s.max()) + 1, -1, np.int64)
    parent_u_of = np.zeros(int(jn_s.max()) + 1)
    parent_spline_of[jn_s] = jn_parent_spline
    parent_u_of[jn_s] = jn_parent_u
    first_nodes = np.flatnonzero(starts)
    ps = parent_spline_of[spline[first_nodes]]
    has_parent = ps >= 0
    junction = np.full(len(first_nodes), -1, np.int64)
    junction[has_parent] = lookup_with_alias(ps[has_parent], parent_u_of[spline[first_nodes]][has_parent])
    parent[first_nodes] = junction
    order = order_of_spline[spline]
    leaf_node = np.zeros(0, np.int64)
    if len(tree.leaves):
        leaf_node = lookup_with_alias(tree.leaf_spline, np.floor(tree.leaf_u))
        leaf_node = np.where(leaf_node < 0, 0, leaf_node)
    return Skeleton(positions=pos, parent=parent, radius=np.maximum(rad, MIN_RADIUS), order=order,
                    leaves=tree.leaves, leaf_node=leaf_node)
