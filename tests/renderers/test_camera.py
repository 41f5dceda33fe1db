"""Camera convention, framing and rigs: known answers, round trips and rejections."""
from __future__ import annotations

import json

import numpy as np
import pytest

from renderers.camera import Camera, CameraError, look_at, make_rig, orthographic_camera, \
    orthographic_half_extent, parse_rig, perspective_camera
from tree_factory import make_skeleton

SIZE = 128


def _front_camera(projection: str) -> Camera:
    E = look_at([0.0, -10.0, 0.0], [0.0, 0.0, 0.0])
    if projection == "perspective":
        K = [[100.0, 0, 63.5], [0, 100.0, 63.5], [0, 0, 1]]
        return Camera(SIZE, SIZE, K, E, "perspective", 1.0, 20.0)
    K = [[32.0, 0, 63.5], [0, 32.0, 63.5], [0, 0, 1]]
    return Camera(SIZE, SIZE, K, E, "orthographic", 1.0, 20.0, 2.0, 2.0)


def test_known_point_projects_to_known_pixel_perspective():
    # Camera 10 m in front (on -Y) looking at the origin: world X is image right, world Z is image up.
    pixels, depth = _front_camera("perspective").project([[1.0, 0.0, 0.5]])
    np.testing.assert_allclose(pixels[0], [63.5 + 10.0, 63.5 - 5.0])
    np.testing.assert_allclose(depth, [10.0])


def test_known_point_projects_to_known_pixel_orthographic():
    pixels, depth = _front_camera("orthographic").project([[1.0, 3.0, 0.5]])
    np.testing.assert_allclose(pixels[0], [63.5 + 32.0, 63.5 - 16.0])
    np.testing.assert_allclose(depth, [13.0])


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_unproject_inverts_project(projection):
    camera = _front_camera(projection)
    points = np.random.default_rng(0).uniform([-2, -2, -2], [2, 2, 2], (50, 3))
    pixels, depth = camera.project(points)
    np.testing.assert_allclose(camera.unproject(pixels, depth), points, atol=1e-9)


@pytest.mark.parametrize("projection", ["perspective", "orthographic"])
def test_opengl_pose_and_projection_agree_with_opencv_pixels(projection):
    camera = _front_camera(projection)
    points = np.random.default_rng(1).uniform([-1.5, -1.5, -1.5], [1.5, 1.5, 1.5], (20, 3))
    pixels, depth = camera.project(points)
    homo = np.concatenate([points, np.ones((20, 1))], axis=1)
    clip = homo @ np.linalg.inv(camera.opengl_pose()).T @ camera.opengl_projection().T
    ndc = clip[:, :3] / clip[:, 3:]
    # OpenGL pixel centres sit at j + 0.5 and its y points up.
    u = (ndc[:, 0] + 1) / 2 * SIZE - 0.5
    v = (1 - ndc[:, 1]) / 2 * SIZE - 0.5
    np.testing.assert_allclose(np.stack([u, v], 1), pixels, atol=1e-9)
    window = (ndc[:, 2] + 1) / 2
    np.testing.assert_allclose(camera.depth_from_window(window), depth, rtol=1e-5)


def test_reverse_depth_projection_flips_the_depth_order():
    camera = _front_camera("perspective")
    near_far = np.array([[0.0, -2.0, 0.0, 1.0], [0.0, 3.0, 0.0, 1.0]])
    clip = near_far @ np.linalg.inv(camera.opengl_pose()).T @ camera.opengl_projection(True).T
    window = (clip[:, 2] / clip[:, 3] + 1) / 2
    assert window[1] < window[0]
    np.testing.assert_allclose(camera.depth_from_window(window, reverse_depth=True), [8.0, 13.0], rtol=1e-6)


def test_camera_dict_round_trips_through_json():
    camera = make_rig("two-view", np.array([[-1, -1, 0], [1, 1, 4.0]]), SIZE, np.random.default_rng(0))[0]
    again = Camera.from_dict(json.loads(json.dumps(camera.to_dict())))
    assert again.to_dict() == camera.to_dict()


def test_tsn4_views_stand_front_right_back_left():
    cameras = make_rig("tsn4", np.array([[-1, -1, 0], [1, 1, 4.0]]), SIZE, np.random.default_rng(0))
    assert [c.name for c in cameras] == ["front", "right", "back", "left"]
    positions = np.array([c.position for c in cameras])
    assert positions[0, 1] < -1 and positions[1, 0] > 1 and positions[2, 1] > 1 and positions[3, 0] < -1
    assert all(c.position[2] > 2.0 for c in cameras)  # 10 degrees above the centre


def test_perspective_framing_fills_ninety_percent_of_the_frame():
    points = np.random.default_rng(2).uniform([-1, -1, 0], [1, 1, 6], (400, 3))
    camera = perspective_camera(points, 0.0, 10.0, SIZE)
    pixels, depth = camera.project(points)
    extent = np.abs(pixels - 63.5).max()
    assert extent == pytest.approx(0.9 * 64, abs=1e-6)
    assert depth.min() > camera.near and depth.max() < camera.far


def test_orthographic_volume_is_the_bounding_box_plus_five_percent():
    points = np.random.default_rng(3).uniform([-1, -2, 0], [1, 2, 5], (400, 3))
    camera = orthographic_camera(points, 0.0, 0.0, SIZE)
    pixels, depth = camera.project(points)
    assert camera.ortho_half_height == pytest.approx(2.5 * 1.05, rel=1e-2)
    assert np.abs(pixels[:, 1] - 63.5).max() == pytest.approx(64 / 1.05, rel=1e-6)
    assert pixels.min() > 0 and pixels.max() < SIZE - 1
    # One metre is the same number of pixels everywhere.
    assert camera.metres_per_pixel(1.0) == camera.metres_per_pixel(50.0) == pytest.approx(1 / camera.K[1, 1])


def test_two_view_cameras_are_orthogonal_and_orthographic():
    cameras = make_rig("two-view", np.array([[-1, -1, 0], [1, 1, 4.0]]), SIZE, np.random.default_rng(0))
    axes = [c.world_to_camera[2, :3] for c in cameras]
    assert all(c.projection == "orthographic" for c in cameras)
    assert abs(np.dot(axes[0], axes[1])) < 1e-9


def test_orbit_has_n_views_per_elevation():
    cameras = make_rig("orbit:6:0,30", np.array([[-1, -1, 0], [1, 1, 4.0]]), SIZE, np.random.default_rng(0))
    assert len(cameras) == 12 and len({c.name for c in cameras}) == 12


def test_jitter_is_seeded_and_plain_rigs_ignore_the_rng():
    pts = np.array([[-1, -1, 0], [1, 1, 4.0]])
    a = make_rig("tsn4:jitter", pts, SIZE, np.random.default_rng(5))
    b = make_rig("tsn4:jitter", pts, SIZE, np.random.default_rng(5))
    c = make_rig("tsn4:jitter", pts, SIZE, np.random.default_rng(6))
    plain = [make_rig("tsn4", pts, SIZE, np.random.default_rng(s))[0] for s in (5, 6)]
    assert np.array_equal(a[0].world_to_camera, b[0].world_to_camera)
    assert not np.allclose(a[0].world_to_camera, c[0].world_to_camera)
    assert np.array_equal(plain[0].world_to_camera, plain[1].world_to_camera)


@pytest.mark.parametrize("rig", ["tsn5", "orbit", "orbit:x", "orbit:0", "two-view:3", "", "jitter", "tsn4:shared",
                                 "two-view:shared:3", "two-view:jitter:shared", "orbit:4:shared"])
def test_unknown_rigs_are_rejected_with_the_allowed_list(rig):
    with pytest.raises(CameraError, match="tsn4"):
        parse_rig(rig)


def _wide_tree_points(seed: int) -> np.ndarray:
    """(N, 3) skeleton node positions of a random test tree stretched along X until its crown is wider than the
    tree is tall: the case where plain two-view frames front and side at different scales."""
    positions = make_skeleton(np.random.default_rng(seed)).positions.astype(np.float64)
    return positions * [3.0, 1.0, 1.0]


@pytest.mark.parametrize("rig", ["two-view:shared", "two-view:shared:jitter"])
@pytest.mark.parametrize("seed", [0, 1])
def test_shared_two_view_puts_each_point_on_the_same_row_in_both_views(rig, seed):
    points = _wide_tree_points(seed)
    front, side = make_rig(rig, points, SIZE, np.random.default_rng(seed))
    rows_front, rows_side = front.project(points)[0][:, 1], side.project(points)[0][:, 1]
    np.testing.assert_allclose(rows_front, rows_side, rtol=0, atol=1e-4)
    # Plain two-view on the same tree does not (what makes the shared rig necessary).
    plain = make_rig("two-view", points, SIZE, np.random.default_rng(seed))
    assert np.abs(plain[0].project(points)[0][:, 1] - plain[1].project(points)[0][:, 1]).max() > 1.0


@pytest.mark.parametrize("seed", [0, 1])
def test_shared_two_view_has_one_scale_that_keeps_the_tree_in_both_frames(seed):
    points = _wide_tree_points(seed)
    cameras = make_rig("two-view:shared", points, SIZE, np.random.default_rng(0))
    plain = make_rig("two-view", points, SIZE, np.random.default_rng(0))
    front, side = cameras
    assert front.metres_per_pixel(1.0) == side.metres_per_pixel(1.0)
    np.testing.assert_array_equal(front.K, side.K)
    assert front.ortho_half_width == side.ortho_half_width == front.ortho_half_height
    assert front.ortho_half_width == max(c.ortho_half_width for c in plain)
    for camera in cameras:
        pixels, depth = camera.project(points)
        assert pixels.min() > 0 and pixels.max() < SIZE - 1
        assert depth.min() > camera.near and depth.max() < camera.far
    assert [c.name for c in cameras] == ["front", "side"]


def test_shared_two_view_jitter_keeps_the_views_orthogonal_and_repeats_with_the_rng():
    points = _wide_tree_points(2)
    a = make_rig("two-view:shared:jitter", points, SIZE, np.random.default_rng(4))
    b = make_rig("two-view:shared:jitter", points, SIZE, np.random.default_rng(4))
    plain = make_rig("two-view:shared", points, SIZE, np.random.default_rng(4))
    assert abs(np.dot(a[0].world_to_camera[2, :3], a[1].world_to_camera[2, :3])) < 1e-9
    assert all(np.array_equal(x.world_to_camera, y.world_to_camera) for x, y in zip(a, b))
    assert not np.allclose(a[0].world_to_camera, plain[0].world_to_camera)


def test_parse_rig_marks_only_the_shared_two_view_as_shared():
    assert parse_rig("two-view:shared").shared_scale and parse_rig("two-view:shared:jitter").jitter
    assert not any(parse_rig(r).shared_scale for r in ("two-view", "two-view:jitter", "tsn4", "orbit:4"))


def test_an_orthographic_camera_with_its_own_fitted_half_extent_is_the_fitted_camera():
    points = _wide_tree_points(3)
    half = orthographic_half_extent(points, 90.0, 0.0)
    fitted = orthographic_camera(points, 90.0, 0.0, SIZE, name="side")
    given = orthographic_camera(points, 90.0, 0.0, SIZE, name="side", half_extent=half)
    assert given.to_dict() == fitted.to_dict()


@pytest.mark.parametrize("half", [0.0, -1.0, float("nan"), float("inf")])
def test_a_half_extent_that_is_not_positive_and_finite_is_rejected(half):
    with pytest.raises(CameraError, match="half_extent"):
        orthographic_camera(_wide_tree_points(0), 0.0, 0.0, SIZE, half_extent=half)


def test_a_composite_rig_gives_each_part_framed_as_alone_named_part_slash_view():
    pts = np.array([[-1, -2, 0], [1, 1, 4.0]])
    cameras = make_rig("tsn4+two-view+two-view:shared", pts, SIZE, np.random.default_rng(0))
    assert [c.name for c in cameras] == ["tsn4/front", "tsn4/right", "tsn4/back", "tsn4/left", "two-view/front",
                                         "two-view/side", "two-view:shared/front", "two-view:shared/side"]
    alone = [*make_rig("tsn4", pts, SIZE, np.random.default_rng(0)),
             *make_rig("two-view", pts, SIZE, np.random.default_rng(0)),
             *make_rig("two-view:shared", pts, SIZE, np.random.default_rng(0))]
    for joined, single in zip(cameras, alone):
        assert np.array_equal(joined.world_to_camera, single.world_to_camera) and np.array_equal(joined.K, single.K)
    assert Camera.from_dict(json.loads(json.dumps(cameras[6].to_dict()))).name == "two-view:shared/front"
    # Jittered parts draw from the one rng in part order: the same seed, the same cameras.
    a = make_rig("tsn4:jitter+two-view", pts, SIZE, np.random.default_rng(3))
    b = make_rig("tsn4:jitter+two-view", pts, SIZE, np.random.default_rng(3))
    assert all(np.array_equal(x.world_to_camera, y.world_to_camera) for x, y in zip(a, b))


@pytest.mark.parametrize("rig, message", [("tsn4+tsn4", "names a rig twice"), ("tsn4+", "is unknown"),
                                          ("tsn4+orbit:0", "orbit needs")])
def test_a_bad_composite_rig_names_the_part(rig, message):
    with pytest.raises(CameraError, match=message):
        make_rig(rig, np.zeros((2, 3)), SIZE, np.random.default_rng(0))
