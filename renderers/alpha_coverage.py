"""Alpha-tested coverage of leaf cards for the library's silhouette measurements: cards shrunk to the area their
texture's alpha covers (one rule for leaves and cluster cards), and a numpy rasterizer for the alpha-cut impostor.

In: a `Camera`, triangles (vertices, faces) with optional UVs and an alpha mask, or cards and an alpha tile.
Out: (H, W) bool coverage, or plain opaque cards (MeshPart / TreeMesh) that depth-only GL passes draw.

Measurement rule (the same for LOD0 leaves, LOD cluster cards and every level, so the comparison is fair): a
card textured with alpha tile A (a single leaf, or a clump for cards that merge several leaves) is drawn as its
own two triangles shrunk about the card's centre by sqrt(f) in both axes, f = the share of texels of A at or
above the files' alpha cutoff (0.5), measured once per tile. The shrunk card covers the same area as the
alpha-tested card; only where inside the card that area lies differs.
"""
from __future__ import annotations

import numpy as np

from species.errors import TreefarmError
from species.studio.lod import card_clumps
from species.tree_mesh import MeshPart, TreeMesh

from .camera import Camera

__all__ = ["triangle_coverage", "triangle_pixels", "pixel_mask", "opaque_fraction", "shrunk_cards", "coverage_tree",
           "CoverageError", "MAX_SAMPLES_PER_CHUNK"]

# Candidate (triangle, pixel) pairs tested at once; bounds memory to a few hundred MB whatever the mesh.
MAX_SAMPLES_PER_CHUNK = 2_000_000


class CoverageError(TreefarmError):
    """Coverage asked of triangles behind the camera, or with UVs/alpha of the wrong shape, or an empty tile."""


def _check(vertices, faces, uvs, texture_shape) -> None:
    """Faces (F, 3); uvs (V, 2) and the alpha texture's shape (h, w) both given (alpha-tested) or neither."""
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise CoverageError(f"faces of shape {faces.shape} are invalid: allowed (F, 3)")
    if (uvs is None) != (texture_shape is None):
        raise CoverageError("uvs and alpha go together: pass both (alpha-tested) or neither (opaque)")
    if uvs is not None and (uvs.shape != (len(vertices), 2) or len(texture_shape) != 2):
        raise CoverageError(f"uvs {uvs.shape} / alpha {tuple(texture_shape)} are invalid: allowed (V, 2) and (h, w)")


def pixel_mask(camera: Camera, pixels: np.ndarray) -> np.ndarray:
    """(H, W) bool of `camera`'s image, True at the flat pixel indices `pixels` (row * W + column)."""
    covered = np.zeros(camera.height * camera.width, bool)
    covered[pixels] = True
    return covered.reshape(camera.height, camera.width)


def triangle_coverage(camera: Camera, vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray | None = None,
                      alpha: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool: pixel centres inside any triangle (and, with `alpha`, on an opaque texel of it).

    vertices : (V, 3) float, metres, world; faces : (F, 3) int; uvs : (V, 2) float, OBJ convention (v = 0 at the
    bottom row of `alpha`); alpha : (h, w) bool, True where the texture is opaque (nearest texel, no filtering).
    Pixel centres are at integer (u, v) as in `Camera`. UVs are interpolated perspective-correctly, as GL does.
    """
    found = triangle_pixels(camera, vertices, faces, uvs, None if alpha is None else np.shape(alpha))
    if alpha is None:
        return pixel_mask(camera, found)
    pixels, texels = found
    return pixel_mask(camera, pixels[np.asarray(alpha, bool).ravel()[texels]])


def triangle_pixels(camera: Camera, vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray | None = None,
                    texture_shape: tuple[int, int] | None = None):
    """The pixel centres inside the triangles, as (P,) int64 flat indices (row * W + column; a pixel inside two
    triangles is listed twice); with `uvs` (V, 2) and `texture_shape` (h, w), also (P,) int64 the flat index
    (row * w + column) of the texel each samples (`triangle_coverage`'s rule). What `triangle_coverage` cuts by
    an alpha mask; worked out once, it serves every texture of the same shape on the same triangles."""
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    textured = uvs is not None
    _check(vertices, faces, uvs, texture_shape)
    found_pixels, found_texels = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    if len(faces) == 0:
        return (found_pixels[0], found_texels[0]) if textured else found_pixels[0]
    pixels, depth = camera.project(vertices)
    if np.any(depth[faces] <= 0):
        raise CoverageError(f"camera {camera.name!r} sees triangles behind it; coverage needs the mesh in front")
    tri = pixels[faces]  # (F, 3, 2)
    # Perspective-correct weights 1 / depth; an orthographic view maps planes affinely.
    inverse_depth = np.ones(faces.shape) if camera.is_orthographic else 1.0 / depth[faces]  # (F, 3)
    lo = np.ceil(tri.min(axis=1) - 1e-9).astype(np.int64)
    hi = np.floor(tri.max(axis=1) + 1e-9).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [camera.width - 1, camera.height - 1])
    edge1, edge2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    det = edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0]
    span = hi - lo + 1
    alive = np.all(span > 0, axis=1) & (np.abs(det) > 1e-12)
    index = np.flatnonzero(alive)
    if textured:
        face_uv = np.asarray(uvs, np.float64)[faces]  # (F, 3, 2)
    counts = span[index, 0] * span[index, 1]
    ends = np.cumsum(counts)
    start = 0
    while start < len(index):  # chunks of whole triangles, each under MAX_SAMPLES_PER_CHUNK candidate pixels
        limit = (ends[start - 1] if start else 0) + MAX_SAMPLES_PER_CHUNK
        stop = max(start + 1, int(np.searchsorted(ends, limit, side="right")))
        chunk, n = index[start:stop], counts[start:stop]
        start = stop
        owner = np.repeat(np.arange(len(chunk)), n)
        local = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
        width = span[chunk, 0][owner]
        row, col = np.divmod(local, width)
        face = chunk[owner]
        px = (lo[face, 0] + col).astype(np.float64)
        py = (lo[face, 1] + row).astype(np.float64)
        dx, dy = px - tri[face, 0, 0], py - tri[face, 0, 1]
        inv = 1.0 / det[face]
        b1 = (dx * edge2[face, 1] - dy * edge2[face, 0]) * inv
        b2 = (dy * edge1[face, 0] - dx * edge1[face, 1]) * inv
        inside = (b1 >= -1e-9) & (b2 >= -1e-9) & (b1 + b2 <= 1.0 + 1e-9)
        face, b1, b2 = face[inside], b1[inside], b2[inside]
        found_pixels.append((py[inside] * camera.width + px[inside]).astype(np.int64))
        if textured:
            # Screen barycentrics weighted by 1 / depth (a plane seen at a slant from a near camera drifts by
            # several texels under affine interpolation); per corner, not as (P, 3) stacks (the same sums).
            weights = [(1.0 - b1 - b2) * inverse_depth[face, 0], b1 * inverse_depth[face, 1],
                       b2 * inverse_depth[face, 2]]
            total = weights[0] + weights[1] + weights[2]
            weights = [w / total for w in weights]
            corner_uv = face_uv[face]
            u, v = (weights[0] * corner_uv[:, 0, c] + weights[1] * corner_uv[:, 1, c]
                    + weights[2] * corner_uv[:, 2, c] for c in range(2))
            h, w = texture_shape
            tcol = np.clip(np.floor(u * w), 0, w - 1).astype(np.int64)
            trow = np.clip(np.floor((1.0 - v) * h), 0, h - 1).astype(np.int64)
            found_texels.append(trow * w + tcol)
    if textured:
        return np.concatenate(found_pixels), np.concatenate(found_texels)
    return np.concatenate(found_pixels)


def opaque_fraction(alpha: np.ndarray) -> float:
    """Share in (0, 1] of opaque texels of an alpha tile (h, w) bool; CoverageError for a tile with none."""
    alpha = np.asarray(alpha, bool)
    if alpha.ndim != 2 or not alpha.any():
        raise CoverageError(f"alpha tile of shape {alpha.shape} with {int(alpha.sum())} opaque texels is "
                            f"invalid: allowed a 2-D tile with at least one opaque texel")
    return float(alpha.mean())


def shrunk_cards(cards: MeshPart, fraction) -> MeshPart:
    """Cards (four corners each, as `leaf_part` makes them) shrunk about their centres by sqrt(fraction) in both
    axes, so each covers `fraction` of its area: the opaque area of an alpha-tested card as two triangles.
    fraction: one number for every card or (C,) one per card. Faces, normals, UVs and attributes are kept;
    vertices (V, 3) float32 metres."""
    if cards.n_vertices % 4:
        raise CoverageError(f"{cards.n_vertices} card vertices are invalid: allowed four per card")
    fractions = np.broadcast_to(np.asarray(fraction, np.float64), (cards.n_vertices // 4,))
    bad = ~((fractions > 0.0) & (fractions <= 1.0))
    if bad.any():
        raise CoverageError(f"coverage fraction {fractions[bad][0]!r} is invalid: allowed (0, 1]")
    corners = np.asarray(cards.vertices, np.float64).reshape(-1, 4, 3)
    centre = corners.mean(axis=1, keepdims=True)
    shrunk = centre + np.sqrt(fractions)[:, None, None] * (corners - centre)
    return MeshPart(shrunk.reshape(-1, 3).astype(np.float32), cards.faces, cards.normals, cards.uvs,
                    dict(cards.attributes))


def coverage_tree(tree: TreeMesh, fraction: float, clump_fraction: float | None = None) -> TreeMesh:
    """The tree with its leaf cards shrunk to the opaque share of the tile each is textured with (see
    `shrunk_cards`), for opaque depth-only coverage passes: `fraction` (the single leaf) for every card, or
    `clump_fraction` for the cards a LOD marks as merged clumps (`species.studio.lod.card_clumps`) when given. The bark
    is kept as it is."""
    if tree.leaves.n_faces == 0:
        return tree
    fractions = fraction if clump_fraction is None else np.where(card_clumps(tree.leaves), clump_fraction, fraction)
    return TreeMesh(bark=tree.bark, leaves=shrunk_cards(tree.leaves, fractions), bark_color=tree.bark_color,
                    leaf_color=tree.leaf_color, name=tree.name)
