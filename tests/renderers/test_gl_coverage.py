"""CoverageRenderer's direct passes: the bark culled as its material is, the leaves and groups never; the same
depths and pixels as pyrender's scene pass (`renderers.gl_depth.DepthRenderer`); any size of target."""
from __future__ import annotations

import numpy as np

from species.tree_mesh import MeshPart, TreeMesh


def test_coverage_culls_the_bark_s_back_faces_as_its_material_does_but_never_the_leaves_or_groups():
    from renderers.gl_coverage import CoverageRenderer
    from renderers.silhouette_metric import switch_camera

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
    from renderers.gl_coverage import CoverageRenderer, RenderPassError
    from renderers.gl_depth import DepthRenderer
    from renderers.maps import combine_parts
    from renderers.silhouette_metric import switch_camera
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
        with pytest.raises(RenderPassError, match="back-face culling"):
            direct.back_depth(cameras[0], np.zeros((cameras[0].height, cameras[0].width), np.float32))
    finally:
        direct.close()
        scene.close()


def test_coverage_of_many_sizes_keeps_a_few_targets_and_the_same_pixels():
    """A silhouette drawn at many sizes in turn (each into a one-byte target of its own) comes out the same as
    when its size is drawn first, and the renderer keeps only a few of those targets."""
    from renderers.gl_coverage import CoverageRenderer
    from renderers.silhouette_metric import switch_camera
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
