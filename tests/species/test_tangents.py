"""Tangent frames for normal maps (species.geometry.tangents): known answers on flat quads, mirrored UVs,
Gram-Schmidt against tilted normals, degenerate UVs, and the invariants on a real bark mesh."""
from __future__ import annotations

import numpy as np
import pytest

from species.geometry import vertex_tangents
from species.meshing import build_mesh
from fixtures.skeletons import random_tree

# A unit quad in the XY plane, facing +z, counter-clockwise.
QUAD = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]])
QUAD_FACES = np.array([[0, 1, 2], [0, 2, 3]])
UP = np.tile([0.0, 0.0, 1.0], (4, 1))


def test_a_quad_mapped_u_along_x_has_tangent_x_and_right_handedness():
    tangents = vertex_tangents(QUAD, UP, QUAD[:, :2], QUAD_FACES)
    np.testing.assert_allclose(tangents, np.tile([1.0, 0.0, 0.0, 1.0], (4, 1)), atol=1e-12)


def test_a_quad_mapped_u_along_y_and_v_along_minus_x_has_tangent_y():
    uvs = np.stack([QUAD[:, 1], 1.0 - QUAD[:, 0]], axis=1) * 3.0  # turned a quarter and tiled 3 times
    tangents = vertex_tangents(QUAD * 2.0, UP, uvs, QUAD_FACES)
    np.testing.assert_allclose(tangents, np.tile([0.0, 1.0, 0.0, 1.0], (4, 1)), atol=1e-12)


def test_mirrored_uvs_give_handedness_minus_one():
    uvs = np.stack([1.0 - QUAD[:, 0], QUAD[:, 1]], axis=1)  # u runs along -x: the image is mirrored
    tangents = vertex_tangents(QUAD, UP, uvs, QUAD_FACES)
    np.testing.assert_allclose(tangents, np.tile([-1.0, 0.0, 0.0, -1.0], (4, 1)), atol=1e-12)
    bitangents = np.cross(UP, tangents[:, :3]) * tangents[:, 3:]
    np.testing.assert_allclose(bitangents, np.tile([0.0, 1.0, 0.0], (4, 1)), atol=1e-12)  # still up the image


def test_tangents_are_made_orthogonal_to_tilted_normals():
    angle = 0.3
    tilted = np.tile([np.sin(angle), 0.0, np.cos(angle)], (4, 1))
    tangents = vertex_tangents(QUAD, tilted, QUAD[:, :2], QUAD_FACES)
    np.testing.assert_allclose(tangents, np.tile([np.cos(angle), 0.0, -np.sin(angle), 1.0], (4, 1)), atol=1e-12)


@pytest.mark.parametrize("uvs", [np.zeros((4, 2)), np.tile([0.3, 0.7], (4, 1)),
                                 np.stack([QUAD[:, 0], QUAD[:, 0]], axis=1)],  # all zero, one point, a line
                         ids=["zero", "point", "collinear"])
def test_degenerate_uvs_give_unit_orthogonal_tangents_without_nan(uvs):
    tangents = vertex_tangents(QUAD, UP, uvs, QUAD_FACES)
    assert np.isfinite(tangents).all()
    np.testing.assert_allclose(np.linalg.norm(tangents[:, :3], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(tangents[:, :3] @ [0.0, 0.0, 1.0], 0.0, atol=1e-12)
    assert (tangents[:, 3] == 1.0).all()


def test_a_triangle_with_degenerate_uvs_adds_nothing_to_its_neighbours():
    uvs = QUAD[:, :2].copy()
    uvs[3] = uvs[2]  # the second triangle's UVs collapse onto a line
    tangents = vertex_tangents(QUAD, UP, uvs, QUAD_FACES)
    np.testing.assert_allclose(tangents[:3], np.tile([1.0, 0.0, 0.0, 1.0], (3, 1)), atol=1e-12)


def test_bark_tangents_are_unit_orthogonal_to_normals_and_follow_u():
    mesh = build_mesh(random_tree(np.random.default_rng(3), n_nodes=200, n_leaves=0), {"name": "tree"})
    bark = mesh.bark
    tangents = vertex_tangents(bark.vertices, bark.normals, bark.uvs, bark.faces)
    assert tangents.shape == (bark.n_vertices, 4) and np.isfinite(tangents).all()
    np.testing.assert_allclose(np.linalg.norm(tangents[:, :3], axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,ij->i", tangents[:, :3], bark.normals), 0.0, atol=1e-5)
    assert set(np.unique(tangents[:, 3])) <= {-1.0, 1.0}
    # Along every edge of a textured triangle (the base disc's UVs are a line) whose u grows and whose v stays
    # put, the edge runs with the tangent.
    uv = bark.uvs[bark.faces].astype(np.float64)
    (du1, dv1), (du2, dv2) = (uv[:, 1] - uv[:, 0]).T, (uv[:, 2] - uv[:, 0]).T
    area = du1 * dv2 - du2 * dv1
    edges = bark.faces[np.abs(area) > 1e-9][:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    du = bark.uvs[edges[:, 1], 0] - bark.uvs[edges[:, 0], 0]
    dv = bark.uvs[edges[:, 1], 1] - bark.uvs[edges[:, 0], 1]
    along_u = (du > 1e-6) & (np.abs(dv) < 1e-9)
    assert along_u.sum() > 100
    step = bark.vertices[edges[along_u, 1]] - bark.vertices[edges[along_u, 0]]
    assert (np.einsum("ij,ij->i", step, tangents[edges[along_u, 0], :3]) > 0).all()
