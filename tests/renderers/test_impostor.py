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
    from renderers.impostor import CoverageRenderer, render_impostor, render_impostors
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


def test_coverage_culls_the_bark_s_back_faces_as_its_material_does_but_never_the_leaves_or_groups():
    from renderers.impostor import CoverageRenderer, switch_camera

    triangle = np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    points = np.concatenate([triangle, triangle + [0.0, 0.5, 0.0], triangle - [0.0, 0.5, 0.0]])
    renderer = CoverageRenderer(64)
    try:
        camera = switch_camera(points, 0.0, 64)
        covered = {}
        for winding in ([[0, 1, 2]], [[0, 2, 1]]):
            part = MeshPart(triangle, np.array(winding), np.zeros((3, 3)), np.zeros((3, 2)))
            as_bark = renderer.coverage(TreeMesh(bark=part, leaves=MeshPart.empty(), name="b"), camera)
            as_leaf = renderer.coverage(TreeMesh(bark=MeshPart.empty(), leaves=part, name="l"), camera)
            renderer.load_groups({"slice": (triangle, np.array(winding), False)})
            as_group = renderer.group_depth(camera, ["slice"]) > 0
            covered[str(winding)] = (int(as_bark.sum()), int(as_leaf.sum()), int(as_group.sum()))
        (front_bark, front_leaf, front_group), (back_bark, back_leaf, back_group) = sorted(covered.values(),
                                                                                        reverse=True)
        assert front_bark == front_leaf == back_leaf == front_group == back_group > 100
        assert back_bark == 0  # seen from behind, a single-sided bark face is culled
    finally:
        renderer.close()


def test_direct_passes_draw_the_depths_and_pixels_of_pyrenders_scene_pass():
    """CoverageRenderer draws its uploads without pyrender's scene walk: each bark part's depth must be bit for
    bit what a DepthRenderer's scene pass gives (both cull it), the leaves' the same pixels (drawn once
    unculled here, there as two culled windings, whose interpolated depths differ in the last bits), and its
    coverage the pixels that depth covers, from views at any azimuth, elevation and size."""
    import pytest

    from renderers.camera import perspective_camera
    from renderers.impostor import CoverageRenderer, ImpostorError, switch_camera
    from renderers.maps import DepthRenderer, combine_parts
    from tree_factory import make_tree

    mesh, _ = make_tree(np.random.default_rng(3))
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    direct, scene = CoverageRenderer(64), DepthRenderer(64)
    try:
        cameras = [switch_camera(points, 33.75, 128), switch_camera(points, 200.0, 512),
                   perspective_camera(points, 71.0, 25.0, 96)]
        for camera in cameras:
            for renderer in (direct, scene):
                renderer.load(mesh)
            ours, theirs = direct.part_depths(camera, True), scene.part_depths(camera, True)
            assert sorted(ours.depths) == sorted(theirs.depths) and len(ours.depths) > 2
            for name, depth in theirs.depths.items():
                if name.startswith("bark"):
                    assert depth.tobytes() == ours.depths[name].tobytes(), name
                else:
                    assert np.array_equal(depth > 0, ours.depths[name] > 0)
                    np.testing.assert_allclose(ours.depths[name], depth, rtol=0, atol=1e-3)
            depth, _, _ = combine_parts(theirs)
            assert 50 < (depth > 0).sum() < depth.size
            assert np.array_equal(direct.coverage(mesh, camera), depth > 0)
        with pytest.raises(ImpostorError, match="back-face culling"):
            direct.back_depth(cameras[0], np.zeros((cameras[0].height, cameras[0].width), np.float32))
    finally:
        direct.close()
        scene.close()


def test_coverage_of_many_sizes_keeps_a_few_targets_and_the_same_pixels():
    """A silhouette drawn at many sizes in turn (each into a one-byte target of its own) comes out the same as
    when its size is drawn first, and the renderer keeps only a few of those targets."""
    from renderers.impostor import CoverageRenderer, switch_camera
    from tree_factory import make_tree

    mesh, _ = make_tree(np.random.default_rng(4))
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    cameras = [switch_camera(points, 30.0, size) for size in range(40, 200, 12)]
    renderer = CoverageRenderer(64)
    try:
        first = [renderer.coverage(mesh, camera) for camera in cameras]
        again = [renderer.coverage(mesh, camera) for camera in reversed(cameras)][::-1]
        for camera, a, b in zip(cameras, first, again):
            assert a.shape == (camera.height, camera.width) and a.any()
            assert np.array_equal(a, b)
        assert len(renderer._renderer._renderer._cover_targets) <= 8 < len(cameras)
    finally:
        renderer.close()
