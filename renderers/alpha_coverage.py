"""Alpha-tested coverage of triangle meshes, rasterized in numpy: which pixel centres a mesh covers when its
texture's alpha cuts the cards (leaf cards, cluster cards, impostor planes) the way an engine's alpha test does.

In: a `Camera`, triangles (vertices, faces) with optional UVs and an alpha mask. Out: (H, W) bool coverage.
"""
from __future__ import annotations

import numpy as np

from species.errors import TreefarmError
from species.tree_mesh import MeshPart, TreeMesh

from .camera import Camera

__all__ = ["triangle_coverage", "alpha_outline", "outlined_cards", "alpha_tested", "CoverageError", "MAX_SAMPLES_PER_CHUNK"]

# Candidate (triangle, pixel) pairs tested at once; bounds memory to a few hundred MB whatever the mesh.
MAX_SAMPLES_PER_CHUNK = 2_000_000
# A traced outline keeps at most this many vertices (one fan triangle each).
MAX_OUTLINE_VERTICES = 12


class CoverageError(TreefarmError):
    """Coverage asked of triangles behind the camera, or with UVs/alpha of the wrong shape."""


def _check(vertices, faces, uvs, alpha) -> None:
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise CoverageError(f"faces of shape {faces.shape} are invalid: allowed (F, 3)")
    if (uvs is None) != (alpha is None):
        raise CoverageError("uvs and alpha go together: pass both (alpha-tested) or neither (opaque)")
    if uvs is not None and (uvs.shape != (len(vertices), 2) or alpha.ndim != 2):
        raise CoverageError(f"uvs {uvs.shape} / alpha {alpha.shape} are invalid: allowed (V, 2) and (h, w)")


def triangle_coverage(camera: Camera, vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray | None = None,
                      alpha: np.ndarray | None = None) -> np.ndarray:
    """(H, W) bool: pixel centres inside any triangle (and, with `alpha`, on an opaque texel of it).

    vertices : (V, 3) float, metres, world; faces : (F, 3) int; uvs : (V, 2) float, OBJ convention (v = 0 at the
    bottom row of `alpha`); alpha : (h, w) bool, True where the texture is opaque (nearest texel, no filtering).
    Pixel centres are at integer (u, v) as in `Camera`. UVs are interpolated affinely in screen space: the
    triangles these views meet (leaves, cluster cards, impostor planes seen from afar) are small against their
    distance, so perspective correction would move a texel by far less than one.
    """
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces, np.int64)
    _check(vertices, faces, uvs, alpha)
    covered = np.zeros(camera.height * camera.width, bool)
    if len(faces) == 0:
        return covered.reshape(camera.height, camera.width)
    pixels, depth = camera.project(vertices)
    if np.any(depth[faces] <= 0):
        raise CoverageError(f"camera {camera.name!r} sees triangles behind it; coverage needs the mesh in front")
    tri = pixels[faces]  # (F, 3, 2)
    lo = np.ceil(tri.min(axis=1) - 1e-9).astype(np.int64)
    hi = np.floor(tri.max(axis=1) + 1e-9).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [camera.width - 1, camera.height - 1])
    edge1, edge2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    det = edge1[:, 0] * edge2[:, 1] - edge1[:, 1] * edge2[:, 0]
    span = hi - lo + 1
    alive = np.all(span > 0, axis=1) & (np.abs(det) > 1e-12)
    index = np.flatnonzero(alive)
    if uvs is not None:
        face_uv = np.asarray(uvs, np.float64)[faces]  # (F, 3, 2)
        texels = np.asarray(alpha, bool)
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
        flat = (py[inside] * camera.width + px[inside]).astype(np.int64)
        if uvs is not None:
            uv = (face_uv[face, 0] + b1[:, None] * (face_uv[face, 1] - face_uv[face, 0])
                  + b2[:, None] * (face_uv[face, 2] - face_uv[face, 0]))
            h, w = texels.shape
            tcol = np.clip(np.floor(uv[:, 0] * w), 0, w - 1).astype(np.int64)
            trow = np.clip(np.floor((1.0 - uv[:, 1]) * h), 0, h - 1).astype(np.int64)
            flat = flat[texels[trow, tcol]]
        covered[flat] = True
    return covered.reshape(camera.height, camera.width)


def alpha_outline(alpha: np.ndarray, max_rows: int = 32) -> np.ndarray:
    """(K, 3, 2) float64 UV triangles (OBJ convention, v up) covering the opaque texels of `alpha` (h, w) bool.

    A star-shaped shape without holes (a leaf, a round clump of leaves) becomes its outer contour, traced a quarter texel
    inside the texel edges (where bilinear alpha at a 0.5 cutoff puts the edge), simplified to at most
    MAX_OUTLINE_VERTICES vertices and fanned from its centroid; any other shape becomes one rectangle per run of
    opaque texels per row, at most `max_rows` rows (rows merged by majority). Coverage of alpha-tested cards
    stays close to exact while the GL renderer draws a few plain opaque triangles per card.
    """
    import cv2

    mask = np.asarray(alpha, bool)
    h, w = mask.shape
    if not mask.any():
        return np.zeros((0, 3, 2))
    fine = np.repeat(np.repeat(mask, 2, axis=0), 2, axis=1).astype(np.uint8)
    contours, _ = cv2.findContours(fine, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    xy = None
    if len(contours) == 1:
        contour = contours[0]
        epsilon = 0.5
        polygon = cv2.approxPolyDP(contour, epsilon, True)
        while len(polygon) > MAX_OUTLINE_VERTICES:  # coarser until few triangles: GL cost scales with them
            epsilon *= 1.2
            polygon = cv2.approxPolyDP(contour, epsilon, True)
        polygon = (polygon[:, 0, :].astype(np.float64) + 0.5) / 2.0
        centre = polygon.mean(axis=0)
        fan = np.stack([np.broadcast_to(centre, polygon.shape), polygon, np.roll(polygon, -1, axis=0)], axis=1)
        e1, e2 = fan[:, 1] - fan[:, 0], fan[:, 2] - fan[:, 0]
        cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        star = np.all(cross > 0) or np.all(cross < 0)  # star-shaped about the centroid
        if star and abs(0.5 * np.abs(cross).sum() - mask.sum()) <= 0.05 * mask.sum():  # and without holes
            xy = fan
    if xy is None:
        step = -(-h // max_rows)
        coarse = np.stack([mask[r:r + step].mean(axis=0) >= 0.5 for r in range(0, h, step)])
        padded = np.pad(coarse.astype(np.int8), ((0, 0), (1, 1)))
        change = np.diff(padded, axis=1)
        run_row, run_start = np.nonzero(change == 1)
        _, run_stop = np.nonzero(change == -1)
        top, bottom = run_row * step, np.minimum((run_row + 1) * step, h)
        quad = np.stack([np.stack([run_start, top], 1), np.stack([run_stop, top], 1),
                         np.stack([run_stop, bottom], 1), np.stack([run_start, bottom], 1)], axis=1)
        xy = np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]]).astype(np.float64)
    return np.stack([xy[..., 0] / w, 1.0 - xy[..., 1] / h], axis=-1)


def outlined_cards(cards: MeshPart, outline: np.ndarray) -> MeshPart:
    """The opaque triangles of alpha-tested cards: `outline` (K, 3, 2) UV triangles (from `alpha_outline`)
    placed on every card of `cards` (four corners per card at UV (0,0), (1,0), (1,1), (0,1), as `leaf_part`
    makes them). Returns a MeshPart of C x K x 3 vertices (normals and UVs carried over)."""
    corners = np.asarray(cards.vertices, np.float64).reshape(-1, 4, 3)
    origin, along_u, along_v = corners[:, 0], corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0]
    uv = outline.reshape(-1, 2)
    vertices = (origin[:, None] + uv[None, :, 0, None] * along_u[:, None] + uv[None, :, 1, None] * along_v[:, None])
    count = vertices.shape[0] * vertices.shape[1]
    normals = np.repeat(np.asarray(cards.normals, np.float64).reshape(-1, 4, 3)[:, 0], uv.shape[0], axis=0)
    return MeshPart(vertices.reshape(-1, 3), np.arange(count).reshape(-1, 3), normals,
                    np.tile(uv, (len(corners), 1)))


def alpha_tested(tree: TreeMesh, leaf_alpha: np.ndarray) -> TreeMesh:
    """The tree with its leaf cards cut to the opaque texels of `leaf_alpha` (h, w) bool (the tile the card
    UVs span), for opaque renderers (GL coverage passes)."""
    if tree.leaves.n_faces == 0:
        return tree
    leaves = outlined_cards(tree.leaves, alpha_outline(leaf_alpha))
    return TreeMesh(bark=tree.bark, leaves=leaves, bark_color=tree.bark_color, leaf_color=tree.leaf_color,
                    name=tree.name)
