"""Leaves as geometry: a leaf texture's alpha traced once into a small outline polygon (a few triangles), and that
template placed on every single-leaf card of a mesh at once, for engines that draw full geometry faster than
alpha-tested cards (Nanite-style foliage).

In: the (h, w) opaque mask of a leaf texture tile (stem at the bottom row, as `leaf_texture` draws it), and leaf
card MeshParts (four vertices a card, corners in `LEAF_CARD_CORNERS` order). Out: a `LeafOutline` (template in
tile UVs and in the card's own frame) and MeshParts of outline polygons, wound like the cards (normal +y of the
card frame).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ..tree_mesh import MeshPart

__all__ = ["LeafOutline", "trace_leaf_outline", "triangulate_polygon", "outline_leaves", "DEFAULT_OUTLINE_VERTICES"]

# Vertices of a traced outline at most: 8 corners, 6 triangles a leaf.
DEFAULT_OUTLINE_VERTICES = 8


@dataclass(frozen=True)
class LeafOutline:
    """A leaf's outline polygon, triangulated.

    uvs   : (K, 2) float32 tile coordinates in [0, 1] (u across the leaf, v from the stem; OBJ convention).
    faces : (T, 3) int32 triangles over the K vertices, wound as the card's (normal +y of the card frame).
    """

    uvs: np.ndarray
    faces: np.ndarray

    @property
    def card_points(self) -> np.ndarray:
        """(K, 3) float32 vertices in the unit card's frame (`LEAF_CARD_CORNERS`: x = u - 0.5, y = 0, z = v)."""
        u, v = self.uvs[:, 0], self.uvs[:, 1]
        return np.stack([u - 0.5, np.zeros_like(u), v], axis=1).astype(np.float32)

    @property
    def n_triangles(self) -> int:
        return len(self.faces)


def _polygon_area(points: np.ndarray) -> float:
    x, y = points[:, 0], points[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def triangulate_polygon(points: np.ndarray) -> np.ndarray:
    """(K - 2, 3) int32 triangles of a simple polygon (K, 2) by ear clipping, each counter-clockwise like the
    polygon made counter-clockwise. A template's few vertices: the loop runs once per leaf texture."""
    points = np.asarray(points, np.float64)
    order = list(range(len(points)))
    if _polygon_area(points) < 0:
        order.reverse()
    triangles = []
    while len(order) > 3:
        for k in range(len(order)):
            a, b, c = order[k - 1], order[k], order[(k + 1) % len(order)]
            pa, pb, pc = points[a], points[b], points[c]
            cross = (pb[0] - pa[0]) * (pc[1] - pa[1]) - (pb[1] - pa[1]) * (pc[0] - pa[0])
            if cross <= 1e-12:
                continue  # a reflex (or flat) corner is no ear
            others = points[[i for i in order if i not in (a, b, c)]]
            if len(others) and _inside_triangle(others, pa, pb, pc).any():
                continue
            triangles.append((a, b, c))
            del order[k]
            break
        else:  # only flat corners left (collinear points): cut the fan that remains
            triangles += [(order[0], order[i], order[i + 1]) for i in range(1, len(order) - 1)]
            order = order[:0]
            break
    if len(order) == 3:
        triangles.append(tuple(order))
    return np.array(triangles, np.int32).reshape(-1, 3)


def _inside_triangle(points: np.ndarray, a, b, c) -> np.ndarray:
    def side(p, q):
        return (q[0] - p[0]) * (points[:, 1] - p[1]) - (q[1] - p[1]) * (points[:, 0] - p[0])

    return (side(a, b) >= 0) & (side(b, c) >= 0) & (side(c, a) >= 0)


def trace_leaf_outline(opaque: np.ndarray, max_vertices: int = DEFAULT_OUTLINE_VERTICES) -> LeafOutline:
    """The outline of the largest opaque region of a leaf tile's mask (h, w) bool (image rows, top first),
    simplified (Douglas-Peucker, the tolerance doubled until at most `max_vertices` corners remain) and
    triangulated once. Raises ParameterError when the mask holds no region to trace."""
    import cv2  # OpenCV for texture images, as the atlases themselves

    if not 3 <= int(max_vertices) <= 64:
        raise ParameterError("max_vertices", max_vertices, "an integer in [3, 64]")
    mask = np.ascontiguousarray(opaque, np.uint8)
    height, width = mask.shape
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        raise ParameterError("leaf texture alpha", "no opaque texel", "a tile with an opaque leaf to trace")
    contour = max(contours, key=cv2.contourArea)
    tolerance = 0.005 * cv2.arcLength(contour, True)
    simple = cv2.approxPolyDP(contour, tolerance, True)
    while len(simple) > max_vertices:
        tolerance *= 1.25
        simple = cv2.approxPolyDP(contour, tolerance, True)
    corners = simple.reshape(-1, 2).astype(np.float64)
    if len(corners) < 3:
        raise ParameterError("leaf texture alpha", f"{len(corners)} corners", "a region with an area to trace")
    # Texel corners at the pixel centres; image rows run down, v runs up from the stem.
    uvs = np.stack([(corners[:, 0] + 0.5) / width, 1.0 - (corners[:, 1] + 0.5) / height], axis=1)
    faces = triangulate_polygon(uvs)
    # Counter-clockwise in (u, v) = (x, z) faces -y; the cards face +y, so every triangle turns round.
    return LeafOutline(uvs.astype(np.float32), faces[:, ::-1].copy())


def outline_leaves(part: MeshPart, outline: LeafOutline, chosen: np.ndarray | None = None) -> MeshPart:
    """The cards of a leaf MeshPart (four vertices a card, UVs `CARD_UVS` at its corners) that `chosen` (C,) bool
    picks (all when None), each replaced by the outline polygon: vertices placed bilinearly between the card's
    corners, normals likewise (then normalised), UVs the outline's in the card's own [0, 1] square, per-vertex
    attributes taken from the card's first corner. Vectorised over cards."""
    corners = part.vertices.reshape(-1, 4, 3)
    chosen = np.ones(len(corners), bool) if chosen is None else np.asarray(chosen, bool)
    corners = corners[chosen].astype(np.float64)
    normals = part.normals.reshape(-1, 4, 3)[chosen].astype(np.float64)
    u, v = outline.uvs[:, 0].astype(np.float64), outline.uvs[:, 1].astype(np.float64)
    # Bilinear weights of the corners (0,0), (1,0), (1,1), (0,1): exact for the cards' parallelograms.
    weights = np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], axis=1)
    vertices = np.einsum("kj,cjd->ckd", weights, corners).reshape(-1, 3)
    normal = np.einsum("kj,cjd->ckd", weights, normals)
    normal /= np.maximum(np.linalg.norm(normal, axis=2, keepdims=True), 1e-12)
    count, k = len(corners), len(outline.uvs)
    faces = (outline.faces[None, :, :] + k * np.arange(count, dtype=np.int32)[:, None, None]).reshape(-1, 3)
    attributes = {name: np.repeat(np.asarray(values).reshape(len(chosen), 4, *np.shape(values)[1:])[chosen, 0],
                                  k, axis=0)
                  for name, values in part.attributes.items()}
    return MeshPart(vertices, faces, normal.reshape(-1, 3), np.tile(outline.uvs, (count, 1)), attributes)
