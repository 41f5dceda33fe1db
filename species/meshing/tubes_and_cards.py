"""Meshing: a Skeleton becomes a TreeMesh of bark tubes (generalized cylinders) and leaf cards.

In: a Skeleton (and optional mesh keys of the parameter dictionary). Out: a TreeMesh, Z up, base at the origin.
"""
from __future__ import annotations

import numpy as np

from ..errors import ParameterError, TreefarmError
from ..geometry.frames import parallel_transport_frames, polyline_tangents
from ..geometry.vectors import cross_rows, row_norms
from ..skeleton import Skeleton
from ..tree_mesh import MeshPart, TreeMesh

__all__ = ["build_mesh", "bark_part", "leaf_part", "radial_segments", "MeshBuildError",
           "DEFAULT_RADIAL_SEGMENTS", "CARD_UVS", "CARD_FACES"]

# Sides of a tube by branch order (digest 3.8): 8 on the trunk, 6 on orders 1-2, 4 beyond.
DEFAULT_RADIAL_SEGMENTS = (8, 6, 6, 4)
# With the default segments, thick branches get more sides so none is wider than this (metres), up to 16.
_MAX_SIDE_WIDTH = 0.12
_MAX_SEGMENTS = 16
# Bark texture tiles: round(circumference / this) tiles around a branch (digest 3.8: TexRepeat).
_BARK_TILE_WIDTH = 0.25
# The bark texture is twice as tall as wide; a tile spans this many tile widths along the branch.
_BARK_TILE_ASPECT = 2.0
# A point of a branch closer to the previous one than this (metres), or than this fraction of its radius,
# is merged into it: such rings would be closer than float32 can separate at tree scale.
_MERGE_DISTANCE = 2e-5
_MERGE_RADIUS_FRACTION = 0.05
# A tip cap is a cone whose apex lies this many tip radii beyond the last ring.
_TIP_CAP_HEIGHT = 0.5


class MeshBuildError(TreefarmError):
    """A skeleton that cannot be meshed (for example a leaf transform that squashes the card flat)."""


# The keys of the `mesh_` family build_mesh reads; any other `mesh_` key is a typo, not a generator's key.
_MESH_KEYS = ("mesh_radial_segments", "mesh_min_segments", "mesh_ground_clear")


def build_mesh(skeleton: Skeleton, params: dict | None = None) -> TreeMesh:
    """Mesh a skeleton: one generalized cylinder per branch and one two-triangle card per leaf.

    skeleton : the tree; its positions are used as they are (base at the origin, Z up, metres).
    params   : optional parameter dictionary, usually the whole growth dictionary. These keys are read when
               present; other keys belong to the generator and are ignored, except that a `mesh_` key not
               listed here raises ParameterError (a mistyped mesh option would otherwise do nothing):
        mesh_radial_segments : list of ints >= 3, tube sides by branch order (the last entry serves all
                               higher orders). Default (8, 6, 6, 4), raised on thick branches so that no
                               side is wider than 0.12 m (at most 16 sides); an explicit list is used as is.
        mesh_min_segments    : int >= 3, lower bound on tube sides for every branch (default 3).
        mesh_ground_clear    : bool, no ring dips below the ground plane z = 0 (rings low beside it lean
                               towards flat; default False: only the trunk's first ring lies flat).
        bark_color, leaf_color : three floats in [0, 1], linear RGB base colours (TreeMesh defaults).
        name                 : str, the tree's name in exported files (default "tree").
    Returns a TreeMesh whose bark carries attributes `order` (V,) uint8 and `branch` (V,) int32, and whose
    leaves carry `node` (V,) int32 (the skeleton node each card hangs from).
    """
    params = {} if params is None else params
    if not isinstance(params, dict):
        raise ParameterError("params", type(params).__name__, "a dict of parameters or None")
    _reject_unknown_mesh_keys(params)
    explicit = "mesh_radial_segments" in params
    by_order = _segments_param(params.get("mesh_radial_segments", DEFAULT_RADIAL_SEGMENTS))
    min_segments = params.get("mesh_min_segments", 3)
    if isinstance(min_segments, bool) or not isinstance(min_segments, (int, np.integer)) or not 3 <= min_segments <= 64:
        raise ParameterError("mesh_min_segments", min_segments, "an integer in [3, 64]")
    colours = {}
    for key in ("bark_color", "leaf_color"):
        if key in params:
            colours[key] = _colour_param(key, params[key])
    name = params.get("name", "tree")
    if not isinstance(name, str) or not name:
        raise ParameterError("name", name, "a non-empty string")
    ground_clear = params.get("mesh_ground_clear", False)
    if not isinstance(ground_clear, (bool, np.bool_)):
        raise ParameterError("mesh_ground_clear", ground_clear, "True or False")
    bark = bark_part(skeleton, by_order, int(min_segments), thick_more=not explicit, ground_clear=bool(ground_clear))
    return TreeMesh(bark=bark, leaves=leaf_part(skeleton), name=name, **colours)


def _reject_unknown_mesh_keys(params: dict) -> None:
    unknown = sorted(key for key in params if isinstance(key, str) and key.startswith("mesh_")
                     and key not in _MESH_KEYS)
    if unknown:
        raise ParameterError(unknown[0], params[unknown[0]], f"a known mesh key: one of {list(_MESH_KEYS)}")


def _segments_param(value) -> tuple[int, ...]:
    allowed = "a non-empty list of integers in [3, 64], one per branch order"
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) == 0:
        raise ParameterError("mesh_radial_segments", value, allowed)
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, np.integer)) or not 3 <= item <= 64:
            raise ParameterError("mesh_radial_segments", value, allowed)
    return tuple(int(v) for v in value)


def _colour_param(key: str, value) -> tuple[float, float, float]:
    allowed = "three numbers in [0, 1] (linear RGB)"
    try:
        rgb = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ParameterError(key, value, allowed) from None
    if rgb.shape != (3,) or not np.all((rgb >= 0) & (rgb <= 1)):
        raise ParameterError(key, value, allowed)
    return tuple(float(c) for c in rgb)


def radial_segments(order: np.ndarray, base_radius: np.ndarray, by_order=DEFAULT_RADIAL_SEGMENTS,
                    min_segments: int = 3, thick_more: bool = True) -> np.ndarray:
    """(B,) int64, tube sides per branch.

    order : (B,) int, branch order; base_radius : (B,) float, metres, radius where the branch starts.
    by_order[min(order, len - 1)] sides, raised (when `thick_more`) so no side exceeds 0.12 m, up to 16.
    """
    table = np.asarray(by_order, np.int64)
    sides = table[np.minimum(np.asarray(order, np.int64), len(table) - 1)]
    if thick_more:
        by_width = np.ceil(2 * np.pi * np.asarray(base_radius, np.float64) / _MAX_SIDE_WIDTH).astype(np.int64)
        sides = np.maximum(sides, np.minimum(by_width, _MAX_SEGMENTS))
    return np.maximum(sides, min_segments)


def _branch_polylines(skeleton: Skeleton, ground_clear: bool = False):
    """Concatenated branch paths with repeated points merged and junction radii fixed.

    Returns (points (K, 3) float64 m, radius (K,) float64 m, offsets (P + 1,) int64, branch (P,) int64):
    only branches left with at least two distinct points, in branch-id order. With `ground_clear` a junction at
    or above the ground plane (z = 0) is not pulled below it.
    """
    path_nodes, path_offsets = skeleton.branch_path_nodes
    nodes = path_nodes.astype(np.int64)
    sizes = np.diff(path_offsets)
    n_paths = len(sizes)
    first = path_offsets[:-1]
    branch = np.repeat(np.arange(n_paths), sizes)
    points = skeleton.positions[nodes].astype(np.float64)
    radius = skeleton.radius[nodes].astype(np.float64)
    # A child branch's first point is its junction on the parent's axis: give it the child's own radius
    # (clamped to the parent's, so the first ring sits inside the parent tube and the joint has no gap).
    junction = skeleton.branch_id[nodes[first]] != np.arange(n_paths)
    junction &= sizes > 1
    at, after = first[junction], first[junction] + 1
    parent_radius = radius[at]
    radius[at] = np.minimum(radius[after], parent_radius)
    # Pull that ring back along the child's direction so its rim hides inside the parent: by half the parent
    # radius at most, and never so far that the ring (radius r) leaves a parent tube of radius R (R - r).
    direction = points[after] - points[at]
    length = row_norms(direction)[:, None]
    pull = np.minimum(0.5 * parent_radius, parent_radius - radius[at])
    pull = np.where(nodes[at] == 0, 0.0, pull)  # at the root that would go below the ground
    if ground_clear:  # nor may a junction low on the trunk be pulled below it
        rising = (direction[:, 2] > 0.0) & (points[at, 2] >= 0.0)
        pull = np.where(rising, np.minimum(pull, points[at, 2] * length[:, 0] / np.maximum(direction[:, 2], 1e-30)),
                        pull)
    pull = pull[:, None]
    points[at] -= np.where(length > 0, pull * direction / np.maximum(length, 1e-30), 0.0)
    # Each pass drops a point too close to the one before it; a path that doubles back (a stem pruned to almost
    # nothing) can leave two kept points together again, so passes repeat until none is dropped.
    is_first = np.zeros(len(nodes), bool)
    is_first[first] = True
    while True:
        keep = np.ones(len(points), bool)
        step = row_norms(np.diff(points, axis=0))
        keep[1:] = step > np.maximum(_MERGE_DISTANCE, _MERGE_RADIUS_FRACTION * radius[1:])
        keep |= is_first
        if keep.all():
            break
        points, radius, branch, is_first = points[keep], radius[keep], branch[keep], is_first[keep]
    counts = np.bincount(branch, minlength=n_paths)
    keep = (counts >= 2)[branch]
    kept_counts = counts[counts >= 2]
    offsets = np.concatenate([[0], np.cumsum(kept_counts)])
    return points[keep], radius[keep], offsets, np.flatnonzero(counts >= 2)


def _ground_clear_tangents(points: np.ndarray, radius: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """(K, 3) unit tangents whose rings stay on or above the ground plane (z = 0): a ring whose centre is less than
    its radius above the ground (and not below it) leans no more than keeps its rim there, turned towards the
    vertical on the side it already points to. A leaning trunk's lowest rings and a low branch flare flat instead
    of dipping into the ground; rings higher up are unchanged."""
    height = points[:, 2]
    near = (height >= 0.0) & (height < radius)
    if not near.any():
        return tangent
    # A ring of radius r about unit tangent t reaches r sqrt(1 - t_z^2) below its centre.
    least_z = np.sqrt(1.0 - (height[near] / radius[near]) ** 2)
    steep = tangent[near]
    leaning = np.abs(steep[:, 2]) < least_z
    if not leaning.any():
        return tangent
    chosen = np.flatnonzero(near)[leaning]
    flat = tangent[chosen, :2]
    flat_length = np.hypot(flat[:, 0], flat[:, 1])[:, None]
    side = np.where(tangent[chosen, 2] < 0.0, -1.0, 1.0)
    tangent = tangent.copy()
    tangent[chosen, :2] = flat / np.maximum(flat_length, 1e-30) * (height[chosen] / radius[chosen])[:, None]
    tangent[chosen, 2] = side * least_z[leaning]
    return tangent


def bark_part(skeleton: Skeleton, by_order=DEFAULT_RADIAL_SEGMENTS, min_segments: int = 3,
              thick_more: bool = True, branch_sides: np.ndarray | None = None,
              tip_cones: np.ndarray | None = None, ground_clear: bool = False) -> MeshPart:
    """Bark: a tube per branch along rotation-minimizing frames, a cone at each tip, a disc under the root.

    The trunk's first ring is horizontal, on the ground plane; with `ground_clear` no other ring dips below it.
    branch_sides : (B,) int per branch of `skeleton`, sides that override `by_order` (levels of detail);
    tip_cones : (B,) bool, which branches end in a cone (default all; an open end of a sub-pixel twig shows
    nothing, so far levels leave it out); ground_clear : no ring or tip cone below z = 0 (`_ground_clear_tangents`).

    Vertex layout: branches grouped by side count (ascending), then in branch order; per branch its rings
    (S + 1 vertices each, the seam duplicated so u runs 0..repeat), then the tip apices of the group's coned
    branches; the root branch's base centre comes last in its group. u = tiles around (round(circumference /
    0.25 m), at least 1), v = arc length / tile height (a tile is twice as tall as wide, like the bark
    texture), both continuous along a branch.
    """
    points, radius, offsets, branch = _branch_polylines(skeleton, ground_clear)
    if len(branch) == 0:
        return _empty_bark()
    sizes = np.diff(offsets)
    starts = offsets[:-1]
    own_node = np.asarray(skeleton.branch_starts)[branch]
    tangent = polyline_tangents(points, offsets)
    # The trunk's first ring lies flat on the ground (z = 0) even when the trunk leans.
    tangent[starts[own_node == 0]] = (0.0, 0.0, 1.0)
    if ground_clear:
        tangent = _ground_clear_tangents(points, radius, tangent)
    tangent, normal, binormal = parallel_transport_frames(points, offsets, tangent)
    point_branch = np.repeat(np.arange(len(branch)), sizes)  # index into `branch`, per point
    order = skeleton.order[own_node].astype(np.int64)
    base_radius = radius[starts]
    if branch_sides is None:
        sides = radial_segments(order, base_radius, by_order, min_segments, thick_more)
    else:
        sides = np.maximum(np.asarray(branch_sides, np.int64)[branch], min_segments)
    coned = np.ones(len(branch), bool) if tip_cones is None else np.asarray(tip_cones, bool)[branch]
    repeat = np.maximum(1.0, np.round(2 * np.pi * base_radius / _BARK_TILE_WIDTH))
    tile_height = _BARK_TILE_ASPECT * 2 * np.pi * base_radius / repeat
    seg = np.zeros(len(points))
    seg[1:] = row_norms(np.diff(points, axis=0))
    seg[starts] = 0.0
    arc = np.cumsum(seg)
    arc -= np.repeat(arc[starts], sizes)
    v_coord = arc / tile_height[point_branch]

    parts = []
    vertex_base = 0
    for side_count in np.unique(sides):
        chosen = np.flatnonzero(sides == side_count)
        part = _tube_group(int(side_count), chosen, offsets, points, radius, tangent, normal, binormal,
                           v_coord, repeat, tile_height, is_root=(own_node == 0), coned=coned,
                           ground_clear=ground_clear)
        part["faces"] += vertex_base
        vertex_base += len(part["vertices"])
        part["order"] = order[chosen][part["local_branch"]].astype(np.uint8)
        part["branch"] = branch[chosen][part["local_branch"]].astype(np.int32)
        parts.append(part)
    cat = {key: parts[0][key] if len(parts) == 1 else np.concatenate([p[key] for p in parts])
           for key in parts[0] if key != "local_branch"}
    return MeshPart(cat["vertices"], cat["faces"], cat["normals"], cat["uvs"],
                    attributes={"order": cat["order"], "branch": cat["branch"]})


def _tube_group(sides: int, chosen: np.ndarray, offsets, points, radius, tangent, normal, binormal,
                v_coord, repeat, tile_height, is_root, coned, ground_clear=False) -> dict[str, np.ndarray]:
    """Rings, tip cones (where `coned`) and (for the root branch) the base disc of the branches `chosen`, all
    S-sided."""
    sizes = np.diff(offsets)[chosen]
    # Point indices of the chosen branches, in order.
    point_ids = np.repeat(offsets[chosen] - np.cumsum(np.concatenate([[0], sizes[:-1]])), sizes) + np.arange(sizes.sum())
    local_branch = np.repeat(np.arange(len(chosen)), sizes)
    n_rings = len(point_ids)
    ring_size = sides + 1
    n_ring_vertices = n_rings * ring_size
    last_ring = np.cumsum(sizes) - 1
    cone = np.flatnonzero(coned[chosen])
    roots = np.flatnonzero(is_root[chosen])
    n_vertices = n_ring_vertices + len(cone) + len(roots)
    vertices = np.empty((n_vertices, 3), np.float32)
    normals = np.empty((n_vertices, 3), np.float32)
    uvs = np.empty((n_vertices, 2), np.float32)

    # Ring vertex k of a ring at point p: p + r (cos a_k n + sin a_k b), worked out in float64 one coordinate at
    # a time ((R, S + 1) arrays with unit stride, twice as fast as broadcasting over (R, S + 1, 3)) and rounded
    # once, into float32.
    angle = 2 * np.pi * np.arange(ring_size) / sides
    cos, sin = np.cos(angle), np.sin(angle)
    cos[-1], sin[-1] = 1.0, 0.0  # the seam column coincides exactly with the first
    ring_radius = radius[point_ids][:, None]
    ring_vertices = vertices[:n_ring_vertices].reshape(n_rings, ring_size, 3)
    ring_normals = normals[:n_ring_vertices].reshape(n_rings, ring_size, 3)
    for axis in range(3):
        coordinate = np.multiply.outer(normal[point_ids, axis], cos)
        coordinate += np.multiply.outer(binormal[point_ids, axis], sin)
        ring_normals[:, :, axis] = coordinate
        coordinate *= ring_radius
        coordinate += points[point_ids, axis][:, None]
        ring_vertices[:, :, axis] = coordinate
    ring_uvs = uvs[:n_ring_vertices].reshape(n_rings, ring_size, 2)
    ring_uvs[..., 0] = repeat[chosen][local_branch][:, None] * (np.arange(ring_size) / sides)[None, :]
    ring_uvs[..., 1] = v_coord[point_ids][:, None]

    # Quads between consecutive rings of the same branch: (a, b, c) and (a, c, d) with b = a + 1, c = a + S + 2,
    # d = a + S + 1, counter-clockwise from outside because the ring runs counter-clockwise about the tangent.
    joined = np.ones(n_rings, bool)
    joined[last_ring] = False
    lower = (np.flatnonzero(joined)[:, None] * ring_size + np.arange(sides)[None, :]).astype(np.int32)
    quad_corners = np.array([0, 1, ring_size + 1, 0, ring_size + 1, ring_size], np.int32)
    quads = (lower.reshape(-1, 1) + quad_corners[None, :]).reshape(-1, 3)

    # Tip cones: one apex past the last ring of each coned branch.
    tip_point = point_ids[last_ring[cone]]
    tip_height = _TIP_CAP_HEIGHT * radius[tip_point]
    # A tip pointing down near the ground stops its cone there (its ring is on or above it).
    falling = ground_clear & (tangent[tip_point, 2] < 0.0) & (points[tip_point, 2] >= 0.0)
    tip_height = np.where(falling, np.minimum(tip_height, points[tip_point, 2] / np.maximum(-tangent[tip_point, 2],
                                                                                           1e-30)), tip_height)
    apex_rows = slice(n_ring_vertices, n_ring_vertices + len(cone))
    vertices[apex_rows] = points[tip_point] + tangent[tip_point] * tip_height[:, None]
    normals[apex_rows] = tangent[tip_point]
    uvs[apex_rows, 0] = 0.5 * repeat[chosen][cone]
    uvs[apex_rows, 1] = v_coord[tip_point] + tip_height / tile_height[chosen][cone]
    apex_index = n_ring_vertices + np.arange(len(cone))
    ring_start = last_ring[cone][:, None] * ring_size + np.arange(sides)[None, :]
    tip_faces = np.stack([ring_start, ring_start + 1, np.broadcast_to(apex_index[:, None], ring_start.shape)],
                         axis=-1).reshape(-1, 3)
    faces = [quads, tip_faces]
    owners = [np.repeat(local_branch, ring_size), cone]

    if len(roots):  # the trunk's bottom: a disc facing down, closing the tube at the ground
        first_ring = (np.cumsum(sizes) - sizes)[roots]
        centre_index = n_ring_vertices + len(cone) + np.arange(len(roots))
        rim = first_ring[:, None] * ring_size + np.arange(sides)[None, :]
        faces.append(np.stack([rim + 1, rim, np.broadcast_to(centre_index[:, None], rim.shape)],
                              axis=-1).reshape(-1, 3))
        base_point = point_ids[first_ring]
        base_rows = slice(n_ring_vertices + len(cone), n_vertices)
        vertices[base_rows] = points[base_point]
        normals[base_rows] = -tangent[base_point]
        uvs[base_rows, 0] = 0.5 * repeat[chosen][roots]
        uvs[base_rows, 1] = 0.0
        owners.append(roots)
    return {"vertices": vertices, "faces": np.concatenate(faces).astype(np.int32), "normals": normals, "uvs": uvs,
            "local_branch": np.concatenate(owners)}


def _empty_bark() -> MeshPart:
    empty = MeshPart.empty()
    return MeshPart(empty.vertices, empty.faces, empty.normals, empty.uvs,
                    attributes={"order": np.zeros(0, np.uint8), "branch": np.zeros(0, np.int32)})


# Card corners as in LEAF_CARD_CORNERS: u across the width, v along the length from the stem.
CARD_UVS = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], np.float32)
# Two triangles per card, wound so their normal is the card's +y (T x ... see leaf_part).
CARD_FACES = np.array([[0, 2, 1], [0, 3, 2]], np.int64)
CARD_FACES_32 = CARD_FACES.astype(np.int32)  # MeshPart's index dtype, so a leaf part's faces are not cast again
for _table in (CARD_UVS, CARD_FACES, CARD_FACES_32):
    _table.setflags(write=False)


def leaf_part(skeleton: Skeleton) -> MeshPart:
    """Leaves: one two-triangle card per leaf transform, normal along the card's +y, UVs (0, 0)-(1, 1).

    Cards are single-sided geometry; the exporters mark the leaf material double-sided.
    """
    corners = skeleton.leaf_corners()  # (M, 4, 3) float32, the vertices as they are stored
    count = len(corners)
    if count == 0:
        return MeshPart(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 2)),
                        attributes={"node": np.zeros(0, np.int32)})
    # Edges in float64 (a float32 corner minus a float64 one is exact), so normals round once, to float32.
    origin = corners[:, 0].astype(np.float64)
    length_edge, width_edge = corners[:, 3] - origin, corners[:, 1] - origin
    # length x width = +y for an unsheared card.
    normal = cross_rows(length_edge, width_edge)
    length = row_norms(normal)
    scale = np.maximum(row_norms(width_edge), row_norms(length_edge))
    flat = length <= 1e-9 * np.maximum(scale * scale, 1e-30)
    if flat.any():
        i = int(np.flatnonzero(flat)[0])
        raise MeshBuildError(f"leaf {i} (node {int(skeleton.leaf_node[i])}) has a transform that maps the "
                             f"card to zero area; leaf transforms need non-zero width and length")
    normal = np.repeat((normal / length[:, None]).astype(np.float32), 4, axis=0)
    faces = (CARD_FACES_32[None, :, :] + 4 * np.arange(count, dtype=np.int32)[:, None, None]).reshape(-1, 3)
    return MeshPart(corners.reshape(-1, 3), faces, normal, np.tile(CARD_UVS, (count, 1)),
                    attributes={"node": np.repeat(skeleton.leaf_node, 4)})
