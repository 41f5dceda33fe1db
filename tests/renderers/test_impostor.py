"""The impostor's slicing of a tree among its planes: every face on the axis or on one plane, shared with the
neighbouring plane only near the sectors' edges."""
from __future__ import annotations

import numpy as np

from renderers.impostor import SECTOR_OVERLAP, sector_groups
from species.tree_mesh import MeshPart, TreeMesh


def _ring_of_triangles(count: int, radius: float) -> MeshPart:
    """`count` small triangles evenly spread in azimuth at `radius` metres from the z axis, 1 m up."""
    angle = (np.arange(count) + 0.5) * 2 * np.pi / count
    centre = np.stack([radius * np.cos(angle), radius * np.sin(angle), np.ones(count)], axis=1)
    offsets = np.array([[0.0, 0.0, 0.0], [0.001, 0.0, 0.0], [0.0, 0.0, 0.001]])
    vertices = (centre[:, None, :] + offsets[None]).reshape(-1, 3).astype(np.float32)
    faces = np.arange(3 * count, dtype=np.int32).reshape(-1, 3)
    normals = np.tile([0.0, 0.0, 1.0], (len(vertices), 1)).astype(np.float32)
    return MeshPart(vertices, faces, normals, np.zeros((len(vertices), 2), np.float32),
                    attributes={"node": np.zeros(len(vertices), np.int32)})


def _memberships(groups: dict, planes: int, part: MeshPart, kind: str = "leaves") -> np.ndarray:
    """(F, planes + 1) bool: which plane groups (and, last, the axis group) of `kind` hold each face, found by
    centroid."""
    centroids = part.vertices[part.faces].mean(axis=1)
    member = np.zeros((part.n_faces, planes + 1), bool)
    for column, name in [(p, f"{kind}_{p}") for p in range(planes)] + [(planes, f"{kind}_axis")]:
        if name not in groups:
            continue
        vertices, faces, _ = groups[name]
        found = vertices[faces].mean(axis=1)
        distance = np.linalg.norm(centroids[:, None, :] - found[None, :, :], axis=2)
        member[:, column] = (distance < 1e-5).any(axis=1)
    return member


def test_faces_off_the_axis_lie_on_one_plane_or_two_neighbouring_ones():
    planes, count = 8, 720
    ring = _ring_of_triangles(count, 1.0)
    tree = TreeMesh(bark=MeshPart.empty(), leaves=ring, name="ring")
    groups = sector_groups(tree, np.array([0.0, 0.0, 1.0]), planes, axis_radius=0.1)
    member = _memberships(groups, planes, ring)
    on_planes = member[:, :planes]
    assert not member[:, planes].any()
    assert set(on_planes.sum(axis=1)) == {1, 2}
    pairs = np.array([np.flatnonzero(row) for row in on_planes if row.sum() == 2])
    assert (((pairs[:, 1] - pairs[:, 0]) % planes == 1) | ((pairs[:, 0] - pairs[:, 1]) % planes == 1)).all()
    # Evenly spread azimuths: the shared margins take 2 x SECTOR_OVERLAP of every sector.
    assert abs((on_planes.sum(axis=1) == 2).mean() - 2 * SECTOR_OVERLAP) < 0.02


def test_faces_near_the_axis_go_on_the_axis_group_alone():
    planes = 8
    ring = _ring_of_triangles(64, 0.05)
    tree = TreeMesh(bark=MeshPart.empty(), leaves=ring, name="core")
    member = _memberships(sector_groups(tree, np.array([0.0, 0.0, 1.0]), planes, axis_radius=0.1), planes, ring)
    assert member[:, planes].all() and not member[:, :planes].any()


def test_a_trunk_off_the_axis_goes_by_sector_like_the_branches():
    # Drawn on every plane, each plane would show it at another place: a smear seen from between them.
    planes = 8
    ring = _ring_of_triangles(64, 1.0)
    trunk = MeshPart(ring.vertices, ring.faces, ring.normals, ring.uvs,
                     attributes={"order": np.zeros(ring.n_vertices, np.uint8)})
    tree = TreeMesh(bark=trunk, leaves=MeshPart.empty(), name="leaning")
    member = _memberships(sector_groups(tree, np.array([0.0, 0.0, 1.0]), planes, axis_radius=0.1), planes, trunk,
                          "bark")
    assert not member[:, planes].any() and set(member[:, :planes].sum(axis=1)) <= {1, 2}


def _sparse_atlas(rng: np.random.Generator):
    from renderers.impostor import ImpostorAtlas

    albedo = np.zeros((64, 128, 4), np.uint8)
    albedo[rng.random((64, 128)) < 0.05] = (10, 200, 30, 255)
    albedo[rng.random((64, 128)) < 0.02] = (90, 60, 30, 255)
    normal = np.full((64, 128, 3), (128, 128, 255), np.uint8)
    return ImpostorAtlas(albedo, normal, np.zeros(3), 1.0, np.arange(8) * 22.5, 32)


def test_grown_alpha_takes_each_tiles_4_neighbours_and_their_colours_never_crossing_tiles():
    atlas = _sparse_atlas(np.random.default_rng(0))
    grown = atlas.grown(1)
    assert atlas.grown(0).albedo.tobytes() == atlas.albedo.tobytes()
    for plane in range(8):
        row, col = atlas.tile_origin(plane)
        before = atlas.albedo[row:row + 32, col:col + 32]
        after = grown.albedo[row:row + 32, col:col + 32]
        opaque = before[..., 3] >= 128
        expected = opaque.copy()
        expected[1:] |= opaque[:-1]
        expected[:-1] |= opaque[1:]
        expected[:, 1:] |= opaque[:, :-1]
        expected[:, :-1] |= opaque[:, 1:]
        assert np.array_equal(after[..., 3] >= 128, expected)  # nothing from the next tile
        assert np.array_equal(after[opaque], before[opaque])  # opaque texels keep their colour
        colours = {tuple(c) for c in before[opaque][:, :3]}
        assert {tuple(c) for c in after[expected & ~opaque][:, :3]} <= colours
    assert grown.normal is atlas.normal and grown.tile == atlas.tile


def test_alpha_growth_out_of_range_is_refused():
    import pytest

    from renderers.impostor import ImpostorError

    atlas = _sparse_atlas(np.random.default_rng(1))
    for texels in (-1, 9, 1.5, True):
        with pytest.raises(ImpostorError, match="alpha growth"):
            atlas.grown(texels)


def test_impostors_of_several_axis_shares_from_one_upload_are_each_shares_own():
    from renderers.gl_coverage import CoverageRenderer
    from renderers.impostor import render_impostor, render_impostors
    from tree_factory import make_tree

    mesh, _ = make_tree(np.random.default_rng(5))
    renderer = CoverageRenderer(64)
    try:
        shares = (0.2, 0.05, 0.35)
        together = render_impostors(renderer, mesh, tile=48, axis_shares=shares)
        for share, atlas in zip(shares, together):
            alone = render_impostor(renderer, mesh, tile=48, axis_share=share)
            assert atlas.albedo.tobytes() == alone.albedo.tobytes()
            assert atlas.normal.tobytes() == alone.normal.tobytes()
        # The shares slice differently: the atlases are not all the same.
        assert len({atlas.albedo.tobytes() for atlas in together}) > 1
    finally:
        renderer.close()
