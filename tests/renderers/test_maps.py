"""Depth, masks, order, normals and silhouette depth: geometry agrees with the mesh and the camera."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy import ndimage
from scipy.spatial import cKDTree

RIGS = ("tsn4", "two-view")


def _raster(camera, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(H, W) bool, pixels whose centre lies inside a projected triangle (the rule GL rasterises by)."""
    h, w = camera.height, camera.width
    image = np.zeros((h, w), bool)
    pixels, _ = camera.project(vertices)
    for a, b, c in pixels[faces]:
        lo = np.maximum(np.floor(np.minimum(np.minimum(a, b), c)), 0).astype(int)
        hi = np.minimum(np.ceil(np.maximum(np.maximum(a, b), c)), [w - 1, h - 1]).astype(int)
        if np.any(hi < lo):
            continue
        v, u = np.mgrid[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1]
        p = np.stack([u, v], -1).astype(np.float64)
        edges = [(q1 - q0)[0] * (p - q0)[..., 1] - (q1 - q0)[1] * (p - q0)[..., 0]
                 for q0, q1 in ((a, b), (b, c), (c, a))]
        inside = (np.minimum.reduce(edges) >= 0) | (np.maximum.reduce(edges) <= 0)
        image[lo[1]:hi[1] + 1, lo[0]:hi[0] + 1] |= inside
    return image


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return (a & b).sum() / (a | b).sum()


@pytest.mark.parametrize("rig", RIGS)
def test_depth_points_lie_on_the_mesh_and_reproject_to_their_pixel(all_outputs, tree, rig):
    mesh, _ = tree
    view = all_outputs[rig][0]
    depth, camera = view.images["depth"], view.camera
    rows, cols = np.nonzero(depth > 0)
    pick = np.random.default_rng(0).choice(len(rows), 400, replace=False)
    pixels = np.stack([cols[pick], rows[pick]], 1).astype(np.float64)
    points = camera.unproject(pixels, depth[rows[pick], cols[pick]])
    both = trimesh.util.concatenate([mesh.bark.to_trimesh(), mesh.leaves.to_trimesh()])
    surface, _ = trimesh.sample.sample_surface(both, 300_000, seed=0)
    distance, _ = cKDTree(surface).query(points)
    spacing = np.sqrt(both.area / len(surface))
    footprint = camera.metres_per_pixel(depth[rows[pick], cols[pick]])
    assert np.median(distance / footprint) < 0.25
    assert np.quantile(distance / footprint, 0.95) < 1.0
    assert spacing < 0.25 * footprint.min()  # the surface sampling is fine enough to tell
    back, _ = camera.project(points)
    assert np.abs(back - pixels).max() < 1.0


@pytest.mark.parametrize("rig", RIGS)
def test_mask_matches_the_projected_triangles(all_outputs, tree, rig):
    mesh, _ = tree
    for view in all_outputs[rig][:2]:
        bark = _raster(view.camera, mesh.bark.vertices, mesh.bark.faces)
        leaves = _raster(view.camera, mesh.leaves.vertices, mesh.leaves.faces)
        mask = view.images["mask"]
        assert _iou(mask > 0, bark | leaves) > 0.95
        assert ((mask == 2) & ~leaves).sum() < 0.05 * (mask == 2).sum()
        assert ((mask == 1) & ~bark).sum() < 0.05 * (mask == 1).sum()


@pytest.mark.parametrize("rig", RIGS)
def test_front_depth_never_exceeds_back_depth(all_outputs, rig):
    for view in all_outputs[rig]:
        front, back, mask = view.images["depth"], view.images["depth_back"], view.images["mask"] > 0
        assert np.all(back[mask] >= front[mask] - 1e-4)
        assert np.all(view.images["silhouette"][..., 1][mask] >= 0)


@pytest.mark.parametrize("rig", RIGS)
def test_back_depth_sees_the_far_side_of_a_tube(all_outputs, rig):
    view = all_outputs[rig][0]
    bark = view.images["mask"] == 1
    gap = view.images["depth_back"][bark] - view.images["depth"][bark]
    # Through the trunk the far wall is about a trunk diameter behind the near one.
    assert np.median(gap) > 0


def test_silhouette_packs_front_gap_and_mask(all_outputs):
    view = all_outputs["two-view"][0]
    sil, mask, depth01 = view.images["silhouette"], view.images["mask"] > 0, view.images["depth01"]
    assert sil.dtype == np.float32 and sil.shape == mask.shape + (3,)
    assert sil.min() >= 0 and sil.max() <= 1
    np.testing.assert_array_equal(sil[..., 2], mask.astype(np.float32))
    np.testing.assert_allclose(sil[..., 0], depth01)
    assert np.all(sil[..., 0][~mask] == 1) and np.all(sil[..., 1][~mask] == 0)


def test_envelope_is_the_closed_crown_with_smooth_depth_near_the_visible_depth(all_outputs):
    for view in all_outputs["two-view"]:
        sil, env = view.images["silhouette"], view.images["silhouette_envelope"]
        fg, crown = sil[..., 2] > 0.5, env[..., 2] > 0.5
        assert env.dtype == np.float32 and env.shape == sil.shape and env.min() >= 0 and env.max() <= 1
        assert np.all(crown[fg]) and crown.sum() > fg.sum()  # the leaves' gaps are closed
        np.testing.assert_array_equal(ndimage.binary_fill_holes(crown), crown)
        assert np.all(env[..., 0][~crown] == 1) and np.all(env[..., 1][~crown] == 0)
        front_leaf, front_env = sil[..., 0], env[..., 0]
        assert abs(front_env[fg].mean() - front_leaf[fg].mean()) < 0.05
        # Pixel-to-pixel change inside the crown: the envelope varies far less than the per-leaf depth.
        inner = ndimage.binary_erosion(fg, iterations=2)
        rough_leaf = np.abs(np.diff(front_leaf, axis=1))[inner[:, 1:] & inner[:, :-1]].mean()
        rough_env = np.abs(np.diff(front_env, axis=1))[inner[:, 1:] & inner[:, :-1]].mean()
        assert rough_env < 0.35 * rough_leaf


def test_envelope_of_a_plane_is_the_plane_and_fills_a_hole_between_its_sides():
    from renderers.camera import orthographic_camera
    from renderers.maps import ENVELOPE_SIGMA_256, envelope_silhouette_map

    camera = orthographic_camera(np.array([[-1.0, -1, 0], [1, 1, 2]]), 0.0, 0.0, 128)
    v, u = np.mgrid[0:128, 0:128]
    disc = (u - 64) ** 2 + (v - 64) ** 2 < 50 ** 2
    ring = disc & ((u - 64) ** 2 + (v - 64) ** 2 > 12 ** 2)
    near = camera.near + (camera.far - camera.near) * (0.2 + 0.004 * u)  # depth01 = 0.2 + 0.004 u
    front = np.where(ring, near, 0.0).astype(np.float32)
    back = np.where(ring, near + 0.3 * (camera.far - camera.near), 0.0).astype(np.float32)
    env = envelope_silhouette_map(camera, front, back)
    np.testing.assert_array_equal(env[..., 2] > 0.5, disc)  # the hole is filled
    # Normalised convolution reproduces a linear surface exactly away from the region's edges.
    far_from_edges = ndimage.distance_transform_edt(ring) > 3 * ENVELOPE_SIGMA_256 / 2
    np.testing.assert_allclose(env[..., 0][far_from_edges], (0.2 + 0.004 * u)[far_from_edges], atol=2e-3)
    np.testing.assert_allclose(env[..., 1][disc], 0.3, atol=2e-3)
    hole = disc & ~ring
    assert np.all((env[..., 0][hole] > 0.2 + 0.004 * 40) & (env[..., 0][hole] < 0.2 + 0.004 * 88))


def test_depth01_spans_near_to_far_with_background_one(all_outputs):
    view = all_outputs["tsn4"][1]
    d01, mask = view.images["depth01"], view.images["mask"] > 0
    assert np.all(d01[~mask] == 1)
    assert 0 < d01[mask].min() < d01[mask].max() < 1


def test_order_ids_cover_exactly_the_visible_bark(all_outputs, tree):
    _, skeleton = tree
    view = all_outputs["tsn4"][0]
    order, mask = view.images["order"], view.images["mask"]
    np.testing.assert_array_equal(order > 0, mask == 1)
    assert set(np.unique(order[order > 0])) <= set(range(1, int(skeleton.order.max()) + 2))
    assert len(np.unique(order[order > 0])) >= 2


def test_normals_face_the_camera(all_outputs):
    view = all_outputs["two-view"][0]
    normals, mask = view.images["normals"], view.images["mask"] > 0
    assert normals.dtype == np.uint8 and normals.shape == mask.shape + (3,)
    assert np.all(normals[mask][:, 2] <= 128)  # z forward: a normal facing the camera has z <= 0
    assert np.all(normals[~mask] == 0)


def test_a_real_meshed_tree_renders_its_projection_with_outward_bark(view_renderer):
    # The bark pass relies on the mesher winding triangles outward (back faces are culled in depth-only
    # passes): then the far wall of every bark tube lies behind its near wall.
    import species

    params = species.sample("maple", np.random.default_rng(0))
    skeleton = species.grow(params, species.rng_for(params))
    mesh = species.build_mesh(skeleton, params)
    view = view_renderer.render(mesh, skeleton, "two-view", ["mask", "depth", "depth_back"],
                                np.random.default_rng(0))[0]
    bark = _raster(view.camera, mesh.bark.vertices, mesh.bark.faces)
    leaves = _raster(view.camera, mesh.leaves.vertices, mesh.leaves.faces)
    assert _iou(view.images["mask"] > 0, bark | leaves) > 0.95
    on_bark = view.images["mask"] == 1
    gap = view.images["depth_back"][on_bark] - view.images["depth"][on_bark]
    assert np.mean(gap > 1e-4) > 0.95
