"""Crown lobes from strokes (seed 000 ch. 5): closed strokes stacked into strips, open strokes stitched over the
holes they leave, into a closed, manifold, outward-oriented mesh that `MeshSpace` accepts.

In: strokes, polylines (K, 3) float metres, Z up (closed ones as rings: see `strokes.stroke_is_closed`). Out: a
`trimesh.Trimesh` whose vertices are the strokes' own samples (plus the centre of an automatic end cap).

A lobe's closed strokes are ordered along their mean normal and joined pairwise by strips: the shorter of two
rings gets Hermite points in its largest gaps until the counts match, the rings are paired with the offset whose
barycentric directions (eq. 5.1) agree best, and every inserted point is merged back into its nearest original
sample (the strip then uses only the strokes' own samples, so neighbouring strips share them). An open stroke caps
the end ring it lies beyond: the ring is resampled to 2 n_open + 2 points, split at the two points its ends point
at, and each half stitched to it. An end ring without an open stroke gets a fan to a point above its centre.
`Lobe` keeps each strip and cap keyed by its strokes, so a new or edited stroke rebuilds only its neighbours, and
writes a Laplacian surface edit back into its strokes, so the strokes are always the lobe's whole state.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import trimesh
from scipy.interpolate import CubicHermiteSpline

from species.errors import TreefarmError
from species.geometry.vectors import row_norms, unit_vectors

from .strokes import resample_polyline, stroke_is_closed
from .surface_edit import laplacian_edit

__all__ = ["LobeError", "Lobe", "lobe_mesh", "barycentric_directions", "FAN_CAP_RISE"]

FAN_CAP_RISE = 0.3        # an automatic end cap's apex rises this share of its ring's mean radius
_MIN_AREA_RATIO = 1e-3    # a ring's area over its perimeter squared below this encloses nothing


class LobeError(TreefarmError):
    """Strokes that cannot make a lobe: too few, no closed one, degenerate, crossing, or an open stroke too many."""


def barycentric_directions(points: np.ndarray) -> np.ndarray:
    """(K, 3) unit vectors, eq. 5.1: normalize(sum over k != i of (p_k - p_i)) for each point of (K, 3)."""
    return unit_vectors(points.sum(axis=0) - len(points) * points)


def _newell_normal(ring: np.ndarray) -> np.ndarray:
    """(3,) the ring's area vector (twice its area, along its normal, right-handed with its order)."""
    return np.cross(ring, np.roll(ring, -1, axis=0)).sum(axis=0)


def _equalize(ring: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """A ring (n, 3) with Hermite points inserted into its largest gaps until it has `count` points, and for each
    point the original sample it merges back into: (count, 3) float64 and (count,) int64."""
    n = len(ring)
    extra = count - n
    if extra <= 0:
        return ring, np.arange(n)
    gaps = row_norms(np.roll(ring, -1, axis=0) - ring)
    # Inserting one point at a time into the largest gap gives gap i the m_i splits whose pieces g_i / (m_i + 1)
    # are among the `extra` largest of all g_i / (j + 1), j >= 1: take those at once.
    pieces = gaps[:, None] / np.arange(2, extra + 2)[None, :]
    chosen = np.argsort(-pieces, axis=None, kind="stable")[:extra]
    splits = np.bincount(chosen // extra, minlength=n)
    closed = np.concatenate([ring, ring[:1]])
    tangents = 0.5 * (np.roll(ring, -1, axis=0) - np.roll(ring, 1, axis=0))
    curve = CubicHermiteSpline(np.arange(n + 1.0), closed, np.concatenate([tangents, tangents[:1]]), axis=0)
    gap = np.repeat(np.arange(n), splits + 1)
    step = np.arange(len(gap)) - np.repeat(np.cumsum(splits + 1) - (splits + 1), splits + 1)
    param = gap + step / (splits + 1)[gap]
    points = curve(param)
    ends = np.stack([gap, (gap + 1) % n], axis=1)
    nearer = row_norms(points - ring[ends[:, 1]]) < row_norms(points - ring[ends[:, 0]])
    return points, np.where(step == 0, gap, ends[np.arange(len(gap)), nearer.astype(int)])


def _strip(row_a: np.ndarray, row_b: np.ndarray, cyclic: bool) -> np.ndarray:
    """(T, 3) int64 triangles between two equally long rows of vertex ids (row a below, both running the same
    way), quads (a_k, a_k+1, b_k+1, b_k) split in two; triangles with a repeated vertex (merged points) dropped."""
    a1, b1 = np.roll(row_a, -1), np.roll(row_b, -1)
    a0, b0 = row_a, row_b
    if not cyclic:
        a0, b0, a1, b1 = a0[:-1], b0[:-1], a1[:-1], b1[:-1]
    faces = np.concatenate([np.stack([a0, a1, b1], axis=1), np.stack([a0, b1, b0], axis=1)])
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return faces[keep]


def _ring_strip(lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Triangles joining ring `lower` (ids 0..n_l-1) to ring `upper` (ids n_l..), both turning positively about
    the lobe's axis, outward-facing."""
    count = max(len(lower), len(upper))
    a, a_map = _equalize(lower, count)
    b, b_map = _equalize(upper, count)
    # Pair with the offset whose barycentric directions agree best over the whole ring (eq. 5.1, summed over all
    # pairs rather than the single best pair, which is steadier on evenly sampled rings).
    agreement = barycentric_directions(a) @ barycentric_directions(b).T
    k = np.arange(count)
    shift = int(np.argmax(agreement[k[None, :], (k[None, :] + k[:, None]) % count].sum(axis=1)))
    return _strip(a_map, len(lower) + b_map[(k + shift) % count], cyclic=True)


def _open_cap(ring: np.ndarray, open_stroke: np.ndarray, top: bool) -> tuple[np.ndarray, np.ndarray]:
    """The cap an open stroke makes over a ring (ids 0..n-1): its vertices (the open stroke, resampled when the
    ring is the denser, ids n..) and triangles, outward-facing (up the axis for a top cap)."""
    n = len(ring)
    if n > 2 * len(open_stroke) + 2:
        open_stroke = resample_polyline(open_stroke, int(np.ceil((n - 2) / 2)))
    n_open = len(open_stroke)
    half = n_open + 1
    points, ring_map = _equalize(ring, 2 * n_open + 2)
    outward = -barycentric_directions(points)
    start_out = unit_vectors(open_stroke[0] - open_stroke[1])
    end_out = unit_vectors(open_stroke[-1] - open_stroke[-2])
    i = np.arange(len(points))
    forward = outward @ start_out + outward[(i + half) % len(points)] @ end_out
    backward = outward @ end_out + outward[(i + half) % len(points)] @ start_out
    if forward.max() >= backward.max():
        anchor, open_ids = int(np.argmax(forward)), n + np.arange(n_open)
    else:
        anchor, open_ids = int(np.argmax(backward)), n + np.arange(n_open)[::-1]
    first = ring_map[(anchor + np.arange(half + 1)) % len(points)]
    second = ring_map[(anchor + half + np.arange(half + 1)) % len(points)]
    faces = np.concatenate([
        _strip(first, np.concatenate([first[:1], open_ids, first[-1:]]), cyclic=False),
        _strip(second, np.concatenate([second[:1], open_ids[::-1], second[-1:]]), cyclic=False)])
    return open_stroke, faces if top else faces[:, ::-1]


def _fan_cap(ring: np.ndarray, axis: np.ndarray, top: bool) -> tuple[np.ndarray, np.ndarray]:
    """A fan from ring (ids 0..n-1) to one apex (id n) raised off its centre along +-axis, outward-facing."""
    centre = ring.mean(axis=0)
    rise = FAN_CAP_RISE * float(row_norms(ring - centre).mean())
    apex = centre + (rise if top else -rise) * axis
    n = len(ring)
    k = np.arange(n)
    faces = np.stack([np.full(n, n), k, (k + 1) % n], axis=1)
    return apex[None, :], faces if top else faces[:, ::-1]


@dataclass(frozen=True)
class _Layout:
    rings: tuple          # closed strokes, (n, 3) each, ordered up the axis, each turning positively about it
    caps: tuple           # (bottom, top): the open stroke capping that end, or None
    axis: np.ndarray      # (3,) unit
    ring_strokes: tuple   # the index in the lobe's strokes of each ring
    cap_strokes: tuple    # the index of each cap's open stroke, or None


def _as_polyline(stroke, index: int) -> np.ndarray:
    points = np.asarray(stroke, np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 2 or not np.all(np.isfinite(points)):
        raise LobeError(f"stroke {index} must be finite points of shape (K >= 2, 3); got shape {points.shape}")
    return points


def _layout(strokes: tuple) -> _Layout:
    if len(strokes) < 2:
        raise LobeError(f"a lobe needs at least 2 strokes (2 closed, or 1 closed and 1 open); got {len(strokes)}")
    closed, opened = [], []
    for index, stroke in enumerate(strokes):
        points = _as_polyline(stroke, index)
        if stroke_is_closed(points):
            if row_norms(points[-1] - points[0]) < 1e-9:
                points = points[:-1]  # the loop's closing sample repeats its first
            if len(points) < 3:
                raise LobeError(f"closed stroke {index} has {len(points)} points; allowed: at least 3")
            closed.append((index, points))
        else:
            opened.append((index, points))
    if not closed:
        raise LobeError(f"a lobe needs at least one closed stroke; all {len(strokes)} strokes are open")
    normals = []
    for index, ring in closed:
        normal = _newell_normal(ring)
        perimeter = float(row_norms(np.roll(ring, -1, axis=0) - ring).sum())
        if np.linalg.norm(normal) / 2 < _MIN_AREA_RATIO * perimeter ** 2:
            raise LobeError(f"closed stroke {index} encloses no area (its points are nearly collinear); allowed: "
                            "a loop round the lobe")
        normals.append(normal)
    signs = np.sign([n @ normals[0] for n in normals])
    axis = unit_vectors((np.array(normals) * signs[:, None]).sum(axis=0))
    if len(closed) == 1:
        if not opened:
            raise LobeError("a lobe needs at least 2 strokes (2 closed, or 1 closed and 1 open); got 1 closed")
        centre = closed[0][1].mean(axis=0)
        if (opened[0][1].mean(axis=0) - centre) @ axis < 0:
            axis = -axis  # the first open stroke caps the top
    height = np.array([ring.mean(axis=0) @ axis for _, ring in closed])
    order = np.argsort(height, kind="stable")
    rings = []
    for k in order:
        ring = closed[k][1]
        rings.append(ring if _newell_normal(ring) @ axis > 0 else ring[::-1].copy())
    for (i, a), (j, b) in zip([closed[k] for k in order[:-1]], [closed[k] for k in order[1:]]):
        if _disc_crossed(a, b) or _disc_crossed(b, a):
            raise LobeError(f"strokes {i} and {j} cross; allowed: closed strokes that stack without crossing")
    caps: list = [None, None]
    for index, points in opened:
        lift = points.mean(axis=0) @ axis
        end = 1 if abs(lift - height[order[-1]]) <= abs(lift - height[order[0]]) else 0
        if len(rings) == 1:
            end = 1 if lift >= height[0] else 0
        if caps[end] is not None:
            raise LobeError(f"open stroke {index} caps the {('bottom', 'top')[end]} of the lobe, which open stroke "
                            f"{caps[end][0]} already caps; allowed: one open stroke per end")
        caps[end] = (index, points)
    return _Layout(tuple(rings), tuple(None if c is None else c[1] for c in caps), axis,
                   tuple(closed[k][0] for k in order), tuple(None if c is None else c[0] for c in caps))


def _disc_crossed(ring: np.ndarray, other: np.ndarray) -> bool:
    """Whether the polyline loop `other` passes through the flat disc spanned by `ring` (its plane, inside it)."""
    centre = ring.mean(axis=0)
    normal = unit_vectors(_newell_normal(ring))
    side = (other - centre) @ normal
    nxt = np.roll(side, -1)
    cross = np.flatnonzero((side > 0) != (nxt > 0))
    if not len(cross):
        return False
    t = side[cross] / (side[cross] - nxt[cross])
    hits = other[cross] + t[:, None] * (np.roll(other, -1, axis=0)[cross] - other[cross])
    u = unit_vectors(ring[0] - centre)
    v = np.cross(normal, u)
    poly = np.stack([(ring - centre) @ u, (ring - centre) @ v], axis=1)
    pts = np.stack([(hits - centre) @ u, (hits - centre) @ v], axis=1)
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    straddle = (y0[None, :] > pts[:, 1:2]) != (y1[None, :] > pts[:, 1:2])
    x_at = x0 + (pts[:, 1:2] - y0) * (x1 - x0) / np.where(y1 == y0, 1.0, y1 - y0)
    inside = (straddle & (pts[:, 0:1] < x_at)).sum(axis=1) % 2 == 1
    return bool(inside.any())


def _read_only(stroke) -> np.ndarray:
    points = np.array(stroke, np.float64)
    points.setflags(write=False)
    return points


def _key(*arrays) -> tuple:
    return tuple(np.ascontiguousarray(a).tobytes() for a in arrays)


@dataclass(frozen=True, eq=False)
class Lobe:
    """A lobe being drawn: its strokes (in drawing order) and the strips and caps already built for them.

    `add_stroke`, `replace_stroke` and `remove_stroke` return a new Lobe that reuses every strip and cap whose
    strokes did not change, so an edit rebuilds only the strips next to the stroke it touched. `mesh()` assembles
    the closed mesh (raises LobeError when the strokes cannot make one).
    """

    strokes: tuple = ()
    parts: dict = field(default_factory=dict, repr=False)  # strip/cap key -> (extra vertices, faces)

    @classmethod
    def from_strokes(cls, strokes, reuse: "Lobe | None" = None) -> "Lobe":
        """A lobe of these strokes (copied, read-only), reusing the strips and caps `reuse` built."""
        return cls(tuple(_read_only(s) for s in strokes), dict(reuse.parts) if reuse else {})

    def add_stroke(self, stroke) -> "Lobe":
        return Lobe.from_strokes(self.strokes + (stroke,), reuse=self)

    def replace_stroke(self, index: int, stroke) -> "Lobe":
        strokes = list(self.strokes)
        strokes[index] = stroke
        return Lobe.from_strokes(strokes, reuse=self)

    def remove_stroke(self, index: int) -> "Lobe":
        return Lobe.from_strokes(self.strokes[:index] + self.strokes[index + 1:], reuse=self)

    def _part(self, used: dict, key: tuple, build):
        part = self.parts.get(key)
        if part is None:
            part = build()
        used[key] = part
        return part

    def mesh(self) -> trimesh.Trimesh:
        """The closed, manifold lobe, faces wound outward (positive volume)."""
        return self._assemble()[0]

    def _assemble(self) -> tuple[trimesh.Trimesh, list]:
        """The mesh, and for each stroke it holds (stroke index, first vertex, count): its samples as meshed
        (a ring in the lobe's turning sense, an open stroke resampled where its ring is the denser)."""
        layout = _layout(self.strokes)
        rings = layout.rings
        offsets = np.concatenate([[0], np.cumsum([len(r) for r in rings])])
        vertices, faces, used = list(rings), [], {}
        sources = [(stroke, int(offsets[k]), len(rings[k])) for k, stroke in enumerate(layout.ring_strokes)]
        for k in range(len(rings) - 1):
            strip = self._part(used, ("strip",) + _key(rings[k], rings[k + 1]),
                               lambda: (np.zeros((0, 3)), _ring_strip(rings[k], rings[k + 1])))[1]
            faces.append(np.where(strip < len(rings[k]), strip + offsets[k], strip - len(rings[k]) + offsets[k + 1]))
        total = int(offsets[-1])
        for end, ring_index in ((0, 0), (1, len(rings) - 1)):
            ring, cap, top = rings[ring_index], layout.caps[end], end == 1
            if cap is not None:
                extra, cap_faces = self._part(used, ("open", top) + _key(ring, cap),
                                              lambda: _open_cap(ring, cap, top))
                sources.append((layout.cap_strokes[end], total, len(extra)))
            else:
                extra, cap_faces = self._part(used, ("fan", top) + _key(ring, layout.axis),
                                              lambda: _fan_cap(ring, layout.axis, top))
            faces.append(np.where(cap_faces < len(ring), cap_faces + offsets[ring_index],
                                  cap_faces - len(ring) + total))
            vertices.append(extra)
            total += len(extra)
        # Keep only what this mesh uses, so the cache follows the strokes; swapped whole, never changed in place,
        # so a Lobe shared between threads is always read whole.
        object.__setattr__(self, "parts", used)
        mesh = trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=False)
        if not (mesh.is_watertight and mesh.is_winding_consistent):
            raise LobeError("the strokes do not make a closed surface (they fold over or cross each other); "
                            "allowed: closed strokes stacked one above the other, open strokes arching over an end")
        if mesh.volume <= 0:
            raise LobeError("the strokes make a surface turned inside out (strokes fold back past each other); "
                            "allowed: closed strokes stacked one above the other, open strokes arching over an end")
        return mesh, sources

    def edit_surface(self, grab, target, radius: float) -> "Lobe":
        """The lobe with its surface dragged from `grab` to `target` ((3,) metres) by Laplacian editing
        (`surface_edit.laplacian_edit`, within `radius` metres along the surface), written back into the strokes:
        the handle is the stroke sample nearest `grab`, and every moved sample moves its stroke, so the strokes
        stay the lobe's whole state (an automatic cap's apex is rebuilt from its ring)."""
        mesh, sources = self._assemble()
        grab = np.asarray(grab, np.float64).reshape(-1)
        target = np.asarray(target, np.float64).reshape(-1)
        if grab.shape != (3,) or not np.all(np.isfinite(grab)):
            raise LobeError(f"the grabbed point is {grab.tolist()}; allowed: three finite coordinates (metres)")
        on_strokes = np.concatenate([np.arange(start, start + count) for _, start, count in sources])
        handle = int(on_strokes[np.argmin(row_norms(mesh.vertices[on_strokes] - grab))])
        moved = laplacian_edit(mesh.vertices, mesh.faces, handle, mesh.vertices[handle] + (target - grab), radius)
        strokes = list(self.strokes)
        for stroke, start, count in sources:
            strokes[stroke] = moved[start: start + count]
        return Lobe.from_strokes(strokes, reuse=self)


def lobe_mesh(strokes) -> trimesh.Trimesh:
    """The closed lobe mesh of a list of strokes, (K, 3) float metres each (see `Lobe`)."""
    return Lobe.from_strokes(strokes).mesh()
