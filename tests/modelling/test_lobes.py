"""Specification of lobes from strokes (farm.modelling.lobes, seed 000 ch. 5): closed, manifold, outward meshes
that bound the space between the strokes; local updates; strokes that cannot make a lobe."""
from __future__ import annotations

import numpy as np
import pytest

from farm.modelling.lobes import barycentric_directions, Lobe, lobe_mesh, LobeError
from species.colonization import MeshSpace


def _ring(radius: float, z: float, count: int, centre=(0.0, 0.0), phase: float = 0.0, tilt: float = 0.0):
    t = phase + np.linspace(0, 2 * np.pi, count, endpoint=False)
    local = np.stack([radius * np.cos(t), radius * np.sin(t), np.zeros(count)], axis=1)
    c, s = np.cos(tilt), np.sin(tilt)
    local = local @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]]).T
    return local + np.array([centre[0], centre[1], z])


def _arch(radius: float, z: float, count: int) -> np.ndarray:
    a = np.linspace(0.15, np.pi - 0.15, count)
    return np.stack([radius * np.cos(a), np.zeros(count), z + radius * np.sin(a)], axis=1)


def _assert_closed_lobe(mesh):
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    edges = np.sort(mesh.edges, axis=1)
    _, uses = np.unique(edges, axis=0, return_counts=True)
    assert np.all(uses == 2)  # manifold: every edge between exactly two faces
    outward = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center - mesh.vertices.mean(axis=0))
    assert np.mean(outward > 0) > 0.95
    MeshSpace(mesh)  # raises on an open mesh


def test_circles_at_several_heights_make_a_closed_lobe_holding_the_space_between():
    strokes = [_ring(0.8, 0.0, 40), _ring(1.2, 1.0, 64)[::-1], _ring(0.6, 2.0, 30)]  # counts and turns differ
    mesh = lobe_mesh(strokes)
    _assert_closed_lobe(mesh)
    space = MeshSpace(mesh)
    between = np.array([[0.3, 0.2, 0.5], [-0.7, 0.1, 0.9], [0.5, -0.4, 1.5], [0.0, 0.3, 1.9]])
    outside = np.array([[1.3, 0.0, 1.0], [0.0, 0.0, 3.0], [0.9, 0.0, 0.1], [0.0, 0.0, -0.6]])
    assert space.contains(between).all() and not space.contains(outside).any()
    assert len(mesh.vertices) == 40 + 64 + 30 + 2  # the strokes' own samples and two cap apexes


def test_a_skewed_pair_pairs_by_barycentric_direction_not_nearest_points():
    lower = _ring(1.0, 0.0, 48)
    upper = _ring(1.0, 1.0, 48, centre=(1.2, 0.4), phase=2.0, tilt=0.5)  # its start sits far round the loop
    mesh = lobe_mesh([lower, upper])
    _assert_closed_lobe(mesh)
    # A straight (untwisted) strip joins each point to the one at the same angle: their midpoints, drawn a little
    # toward the lobe's axis, lie inside.
    same_angle = _ring(1.0, 1.0, 48, centre=(1.2, 0.4), tilt=0.5)
    middle = 0.5 * (lower + same_angle)
    axis_point = 0.5 * (lower.mean(axis=0) + same_angle.mean(axis=0))
    assert MeshSpace(mesh).contains(axis_point + 0.85 * (middle - axis_point)).all()
    untwisted = lobe_mesh([lower, same_angle])
    assert mesh.volume == pytest.approx(untwisted.volume, rel=0.02)


def test_a_closed_and_an_open_stroke_stitch_into_a_dome():
    mesh = lobe_mesh([_ring(1.0, 0.0, 30), _arch(1.0, 0.0, 12)])
    _assert_closed_lobe(mesh)
    assert MeshSpace(mesh).contains(np.array([[0.05, 0.02, 0.5], [0.1, -0.3, 0.4], [-0.3, 0.3, 0.3]])).all()
    assert mesh.bounds[1, 2] == pytest.approx(_arch(1.0, 0.0, 12)[:, 2].max())


def test_open_strokes_can_cap_both_ends_of_a_stack():
    bottom = _arch(0.9, 0.0, 9) * np.array([1, 1, -1])
    mesh = lobe_mesh([_ring(1.0, 0.0, 24), _ring(1.0, 1.0, 26), _arch(1.0, 1.0, 10), bottom])
    _assert_closed_lobe(mesh)
    assert mesh.bounds[0, 2] < -0.8 and mesh.bounds[1, 2] > 1.9


def test_barycentric_direction_points_at_the_rest_of_the_stroke():
    ring = _ring(1.0, 0.0, 12)
    assert np.allclose(barycentric_directions(ring), -ring / np.linalg.norm(ring, axis=1, keepdims=True))


def test_a_new_stroke_rebuilds_only_its_neighbouring_strips():
    a, b, c = _ring(1.0, 0.0, 30), _ring(1.1, 1.0, 34), _ring(0.9, 2.0, 28)
    first = Lobe.from_strokes([a, c])
    first.mesh()
    strip_ac = next(part for key, part in first.parts.items() if key[0] == "strip")
    second = first.add_stroke(b)  # drawn between the two: the a-c strip gives way to a-b and b-c
    mesh = second.mesh()
    strips = [part for key, part in second.parts.items() if key[0] == "strip"]
    assert len(strips) == 2 and all(part is not strip_ac for part in strips)
    third = second.add_stroke(_arch(0.9, 2.0, 10))  # a cap on top: both strips are reused as they are
    third.mesh()
    assert sum(any(part is s for s in strips) for part in third.parts.values()) == 2
    again = lobe_mesh([a, b, c])
    assert np.array_equal(mesh.vertices, again.vertices) and np.array_equal(mesh.faces, again.faces)


def test_replacing_a_stroke_keeps_the_far_strip():
    a, b, c = _ring(1.0, 0.0, 30), _ring(1.1, 1.0, 34), _ring(0.9, 2.0, 28)
    lobe = Lobe.from_strokes([a, b, c])
    lobe.mesh()
    kept = lobe.parts[next(k for k in lobe.parts if k[0] == "strip" and k[1] == a.tobytes())]
    edited = lobe.replace_stroke(2, _ring(0.7, 2.2, 28))
    _assert_closed_lobe(edited.mesh())
    assert any(part is kept for part in edited.parts.values())
    assert len(edited.remove_stroke(1).mesh().vertices) == 30 + 28 + 2


@pytest.mark.parametrize("strokes, message", [
    ([_ring(1.0, 0.0, 20)], "at least 2 strokes"),
    ([_arch(1.0, 0.0, 10), _arch(1.0, 1.0, 10)], "at least one closed"),
    ([_ring(1.0, 0.0, 20), np.concatenate([np.linspace([0, 0, 1], [1, 0, 1], 10),
                                          np.linspace([1, 0, 1], [0, 0, 1], 10)])], "no area"),
    ([_ring(1.0, 0.0, 30), _ring(1.0, 0.0, 30, centre=(0.5, 0.0), tilt=np.pi / 2)], "cross"),
    ([_ring(1.0, 0.0, 20), _arch(1.0, 0.0, 8), _arch(0.8, 0.0, 8)], "one open stroke per end"),
    ([_ring(1.0, 0.0, 20), np.full((4, 3), np.nan)], "finite"),
])
def test_strokes_that_cannot_make_a_lobe_are_refused(strokes, message):
    with pytest.raises(LobeError, match=message):
        lobe_mesh(strokes)


def test_a_surface_edit_is_written_back_into_the_strokes():
    strokes = [_ring(0.8, 0.0, 40), _ring(1.0, 1.0, 40)[::-1], _ring(0.6, 2.0, 40), _arch(0.6, 2.0, 10)]
    lobe = Lobe.from_strokes(strokes)
    before = lobe.mesh()
    edited = lobe.edit_surface([1.0, 0.0, 1.0], [1.4, 0.0, 1.1], radius=0.8)
    after = edited.mesh()
    _assert_closed_lobe(after)
    assert after.volume > before.volume and np.array_equal(after.faces, before.faces)
    assert np.any(np.all(np.isclose(edited.strokes[1], [1.4, 0.0, 1.1]), axis=1))  # the grabbed sample moved
    assert np.array_equal(edited.strokes[0], strokes[0])  # the far ring did not
    assert np.array_equal(Lobe.from_strokes(edited.strokes).mesh().vertices, after.vertices)  # strokes are the state
