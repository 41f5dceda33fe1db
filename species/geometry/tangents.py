"""Per-vertex tangent frames of a UV-mapped triangle mesh, for normal maps (glTF's TANGENT attribute).

In: vertices, normals, UVs and faces as plain arrays. Out: (V, 4) tangents, xyz a unit vector along +u orthogonal to
the normal, w = +1 or -1 the handedness, so that cross(normal, xyz) * w points up the image (+v).
"""
from __future__ import annotations

import numpy as np

from .frames import _reference_normals
from .vectors import cross_rows, unit_vectors

__all__ = ["vertex_tangents", "DEGENERATE_UV_SINE"]

# A triangle whose two UV edges are closer to parallel than this sine (or of zero length) spans no texture
# directions: it contributes nothing, rather than a tangent of arbitrary sign.
DEGENERATE_UV_SINE = 1e-9


def vertex_tangents(vertices: np.ndarray, normals: np.ndarray, uvs: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 4) float64 tangents of a triangle mesh (see the module docstring).

    vertices : (V, 3) float, any units and frame; normals : (V, 3) float, unit, same frame; uvs : (V, 2) float,
    OBJ convention (v = 0 at the bottom of the image, as glTF's tangent space reads "+y up" in the normal map);
    faces : (F, 3) int, counter-clockwise.

    Each triangle adds its dPos/du and dPos/dv, weighted by its UV area, to its three corners; each vertex's sum
    is made orthogonal to its normal (Gram-Schmidt) and unit, and w is the sign of the summed dPos/dv against
    cross(normal, tangent). A vertex whose triangles all have degenerate UVs gets some unit vector orthogonal to
    its normal and w = +1, never NaN.
    """
    vertices = np.asarray(vertices, np.float64)
    uvs = np.asarray(uvs, np.float64)
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    normals = unit_vectors(np.asarray(normals, np.float64))
    edge1 = vertices[faces[:, 1]] - vertices[faces[:, 0]]
    edge2 = vertices[faces[:, 2]] - vertices[faces[:, 0]]
    duv1 = uvs[faces[:, 1]] - uvs[faces[:, 0]]
    duv2 = uvs[faces[:, 2]] - uvs[faces[:, 0]]
    det = duv1[:, 0] * duv2[:, 1] - duv2[:, 0] * duv1[:, 1]
    # The solution of [e1 e2] = [dP/du dP/dv] [duv1 duv2] is the numerators below over det; multiplying by |det|
    # (the sign of det) weights each triangle by its UV area and needs no division.
    span = np.linalg.norm(duv1, axis=1) * np.linalg.norm(duv2, axis=1)
    sign = np.where(np.abs(det) > DEGENERATE_UV_SINE * span, np.sign(det), 0.0)[:, None]
    face_u = (duv2[:, 1:2] * edge1 - duv1[:, 1:2] * edge2) * sign
    face_v = (duv1[:, 0:1] * edge2 - duv2[:, 0:1] * edge1) * sign
    along_u = _corner_sums(face_u, faces, len(vertices))
    along_v = _corner_sums(face_v, faces, len(vertices))
    tangent = unit_vectors(along_u - normals * np.einsum("ij,ij->i", along_u, normals)[:, None])
    undefined = ~tangent.any(axis=1)
    tangent[undefined] = _reference_normals(normals[undefined])
    handedness = np.where(np.einsum("ij,ij->i", cross_rows(normals, tangent), along_v) < 0.0, -1.0, 1.0)
    return np.concatenate([tangent, handedness[:, None]], axis=1)


def _corner_sums(per_face: np.ndarray, faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(V, 3): the sum of `per_face` (F, 3) over the faces each vertex is a corner of."""
    corners = faces.reshape(-1)
    values = np.repeat(per_face, 3, axis=0)
    return np.stack([np.bincount(corners, values[:, k], n_vertices) for k in range(3)], axis=1)
