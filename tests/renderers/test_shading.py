"""Base-colour shading of the library's previews: the Lambert term with its ambient floor, in linear light."""
from __future__ import annotations

import numpy as np

from renderers.shading import AMBIENT, LIGHT_DIRECTION, lambert_srgb
from species.meshing.textures import linear_to_srgb


def test_a_face_turned_to_the_light_shows_its_full_base_colour():
    albedo = np.array([[0.2, 0.5, 0.8]])
    expected = np.round(linear_to_srgb(albedo) * 255).astype(np.uint8)
    np.testing.assert_array_equal(lambert_srgb(-LIGHT_DIRECTION[None, :], albedo), expected)


def test_a_face_turned_away_keeps_the_ambient_share():
    albedo = np.array([[0.2, 0.5, 0.8]])
    expected = np.round(linear_to_srgb(albedo * AMBIENT) * 255).astype(np.uint8)
    np.testing.assert_array_equal(lambert_srgb(LIGHT_DIRECTION[None, :], albedo), expected)


def test_shading_never_brightens_past_the_base_colour():
    rng = np.random.default_rng(0)
    normals = rng.normal(size=(500, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    albedo = rng.uniform(0, 1, (500, 3))
    shaded = lambert_srgb(normals, albedo).astype(int)
    assert np.all(shaded <= np.round(linear_to_srgb(albedo) * 255).astype(int))
