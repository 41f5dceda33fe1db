"""Specification of the shape edits (farm.modelling.surface_edit): Laplacian surface drags (eq. 5.3-5.5) and
quadratic Bezier stroke drags (eq. 5.2)."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from farm.modelling.lobes import lobe_mesh
from farm.modelling.surface_edit import bezier_drag, edit_region, EditError, laplacian_edit, umbrella_laplacian
from species.colonization import MeshSpace


@pytest.fixture(scope="module")
def sphere():
    return trimesh.creation.icosphere(subdivisions=3)


def test_the_handle_reaches_its_target_and_far_vertices_stay_exactly(sphere):
    handle = 0
    target = sphere.vertices[handle] * 1.5
    moved = laplacian_edit(sphere.vertices, sphere.faces, handle, target, radius=0.8)
    assert np.array_equal(moved[handle], target)
    far = ~edit_region(sphere.vertices, sphere.faces, handle, 0.8)
    assert far.sum() > len(far) // 2
    assert np.array_equal(moved[far], sphere.vertices[far])


def test_the_region_round_the_handle_follows_it_smoothly(sphere):
    handle = 5
    direction = sphere.vertices[handle]
    moved = laplacian_edit(sphere.vertices, sphere.faces, handle, direction * 1.4, radius=0.8)
    shift = (moved - sphere.vertices) @ direction
    ring = np.unique(sphere.faces[np.any(sphere.faces == handle, axis=1)])
    ring = ring[ring != handle]
    assert np.all((shift[ring] > 0.05) & (shift[ring] < 0.4))  # neighbours follow part of the way
    assert np.all(np.isfinite(moved))


def test_an_edited_lobe_is_still_a_closed_growth_space():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    rings = [np.stack([r * np.cos(t), r * np.sin(t), np.full(40, z)], axis=1) for r, z in ((0.8, 0), (1, 1), (0.6, 2))]
    mesh = lobe_mesh(rings)
    handle = 40 + 10  # a sample of the middle stroke
    vertices = laplacian_edit(mesh.vertices, mesh.faces, handle, mesh.vertices[handle] * [1.5, 1.5, 1.0], 1.0)
    edited = trimesh.Trimesh(vertices, mesh.faces, process=False)
    assert edited.is_watertight and edited.volume > mesh.volume
    near_handle = np.array([[1.2 * np.cos(t[10] + 0.01), 1.2 * np.sin(t[10] + 0.01), 0.97]])
    assert MeshSpace(edited).contains(near_handle).all() and not MeshSpace(mesh).contains(near_handle).any()


def test_the_umbrella_laplacian_rows_sum_to_zero(sphere):
    laplacian = umbrella_laplacian(sphere.faces, len(sphere.vertices))
    assert np.allclose(np.asarray(laplacian.sum(axis=1)).ravel(), 0.0)
    assert np.allclose(laplacian.diagonal(), 1.0)


def test_a_bezier_drag_passes_through_the_target_and_keeps_the_rest():
    stroke = np.stack([np.linspace(0, 2, 41), np.zeros(41), np.zeros(41)], axis=1)
    dragged = bezier_drag(stroke, 20, [1.0, 0.5, 0.2], span=8)
    assert np.allclose(dragged[20], [1.0, 0.5, 0.2])
    assert np.array_equal(dragged[:12], stroke[:12]) and np.array_equal(dragged[29:], stroke[29:])
    second = np.diff(dragged[12:29], n=2, axis=0)  # a quadratic in evenly stepped t: constant second difference
    assert np.allclose(second, second[0])


def test_a_bezier_drag_wraps_round_a_closed_stroke_and_moves_an_open_end():
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = np.stack([np.cos(t), np.sin(t), np.zeros(32)], axis=1)
    dragged = bezier_drag(ring, 0, [1.5, 0.0, 0.0], span=4)
    assert np.allclose(dragged[0], [1.5, 0, 0]) and not np.allclose(dragged[30], ring[30])
    assert np.array_equal(dragged[5:28], ring[5:28])
    line = np.stack([np.linspace(0, 1, 11), np.zeros(11), np.zeros(11)], axis=1)
    assert np.allclose(bezier_drag(line, 0, [0, 0.3, 0], span=4)[0], [0, 0.3, 0])


@pytest.mark.parametrize("call, message", [
    (lambda m: laplacian_edit(m.vertices, m.faces, -1, [0, 0, 0], 1.0), "handle"),
    (lambda m: laplacian_edit(m.vertices, m.faces, 0, [0, np.nan, 0], 1.0), "finite"),
    (lambda m: laplacian_edit(m.vertices, m.faces, 0, [0, 0, 0], 0.0), "radius"),
    (lambda m: bezier_drag(m.vertices[:10], 10, [0, 0, 0]), "index"),
])
def test_bad_edits_are_refused(sphere, call, message):
    with pytest.raises(EditError, match=message):
        call(sphere)
