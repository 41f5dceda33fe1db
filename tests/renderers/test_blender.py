"""The Blender worker and its adapter: environment lookup, camera conversion, job results, photo files, errors.

Blender runs for real (`.venv-blender`, built by `make env`); a missing environment fails with that hint.
"""
from __future__ import annotations

import json
import math
import sys

import numpy as np
import pytest

from renderers.blender import BlenderError, blender_python, glb_info, load_view, render_photos, resize_camera, \
    run_job, run_jobs
from renderers.blender_worker.cameras import CameraConversionError, blender_camera_settings
from renderers.camera import Camera, look_at, make_rig

PHOTO_SIZE = 64


def _camera(projection: str = "perspective", cx: float = 63.5, K01: float = 0.0, fy: float = 100.0) -> Camera:
    E = look_at([3.0, -10.0, 2.0], [0.0, 0.0, 1.0])
    if projection == "perspective":
        return Camera(128, 128, [[100.0, K01, cx], [0, fy, 63.5], [0, 0, 1]], E, "perspective", 1.0, 20.0)
    return Camera(128, 128, [[32.0, 0, 63.5], [0, 32.0, 63.5], [0, 0, 1]], E, "orthographic", 1.0, 20.0, 2.0, 2.0)


# ------------------------------------------------------------------------------ environment
def test_blender_python_names_make_env_when_the_environment_is_missing(monkeypatch, tmp_path):
    monkeypatch.setenv("TREEFARM_BLENDER_PYTHON", str(tmp_path / "no-such-python"))
    with pytest.raises(BlenderError, match="make env"):
        blender_python()


def test_blender_python_honours_the_override(monkeypatch):
    monkeypatch.setenv("TREEFARM_BLENDER_PYTHON", sys.executable)
    assert str(blender_python()) == sys.executable


def test_blender_environment_is_built():
    # CI runs `make env` first; without it this fails with the message to run it (no silent skip).
    assert blender_python().is_file()


# ------------------------------------------------------------------------------ camera conversion
def test_blender_camera_looks_down_its_minus_z_with_y_up():
    camera = _camera()
    pose = np.array(blender_camera_settings(camera.to_dict())["matrix_world"])
    forward, down = camera.world_to_camera[2, :3], camera.world_to_camera[1, :3]
    np.testing.assert_allclose(-pose[:3, 2], forward, atol=1e-12)
    np.testing.assert_allclose(pose[:3, 1], -down, atol=1e-12)
    np.testing.assert_allclose(pose[:3, 3], camera.position, atol=1e-12)


def test_blender_lens_reproduces_the_horizontal_field_of_view():
    settings = blender_camera_settings(_camera().to_dict())
    fov_ours = 2 * math.atan(128 / 2 / 100.0)
    fov_blender = 2 * math.atan(settings["sensor_width"] / 2 / settings["lens"])
    assert settings["type"] == "PERSP" and math.isclose(fov_ours, fov_blender, rel_tol=1e-12)


def test_centred_principal_point_needs_no_shift():
    settings = blender_camera_settings(_camera().to_dict())
    assert settings["shift_x"] == 0.0 and settings["shift_y"] == 0.0


def test_principal_point_right_of_centre_shifts_the_view_left():
    # The optical axis meets the image 10 px right of centre, so the window moves left by 10/128 widths.
    settings = blender_camera_settings(_camera(cx=73.5).to_dict())
    assert math.isclose(settings["shift_x"], -10 / 128, rel_tol=1e-12)


def test_orthographic_scale_spans_the_view_width():
    settings = blender_camera_settings(_camera("orthographic").to_dict())
    assert settings["type"] == "ORTHO" and math.isclose(settings["ortho_scale"], 4.0, rel_tol=1e-12)


@pytest.mark.parametrize("bad", [{"K01": 0.5}, {"fy": 101.0}])
def test_cameras_blender_cannot_reproduce_are_rejected(bad):
    with pytest.raises(CameraConversionError):
        blender_camera_settings(_camera(**bad).to_dict())


def test_non_rigid_pose_is_rejected():
    data = _camera().to_dict()
    data["world_to_camera"][0][0] *= 2.0
    with pytest.raises(CameraConversionError, match="orthonormal"):
        blender_camera_settings(data)


def test_resized_camera_sees_the_same_point_at_the_same_image_fraction():
    camera = _camera(cx=70.0)
    small = resize_camera(camera, 48, 48)
    point = [[0.7, 0.2, 1.9]]
    (u, v), = camera.project(point)[0]
    (us, vs), = small.project(point)[0]
    np.testing.assert_allclose([(us + 0.5) / 48, (vs + 0.5) / 48], [(u + 0.5) / 128, (v + 0.5) / 128])


# ------------------------------------------------------------------------------ jobs
@pytest.fixture(scope="module")
def tree_glb(tree):
    mesh, _ = tree
    return mesh.to_glb()


@pytest.fixture(scope="module")
def photos(tree, tree_glb, tmp_path_factory):
    mesh, _ = tree
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    cameras = make_rig("orbit:2", points, PHOTO_SIZE, np.random.default_rng(0))
    return render_photos(tree_glb, cameras, tmp_path_factory.mktemp("photos"), samples=4)


def test_info_counts_the_glb_triangles_per_part(tree, tree_glb):
    mesh, _ = tree
    info = glb_info(tree_glb)
    parts = {row["part"]: row["triangles"] for row in info["objects"]}
    assert parts == {"bark": mesh.bark.n_faces, "leaves": mesh.leaves.n_faces}
    assert info["triangles"] == mesh.n_faces


def test_info_bounds_are_the_tree_bounds_in_our_z_up_world(tree, tree_glb):
    mesh, _ = tree
    np.testing.assert_allclose(glb_info(tree_glb)["bounds"], mesh.bounds, atol=1e-4)


@pytest.mark.slow
def test_photos_write_one_image_depth_and_mask_per_camera(photos):
    assert len(photos.images) == len(photos.depths) == len(photos.masks) == len(photos.cameras) == 2
    for index in range(2):
        view = load_view(photos, index)
        assert view["photo"].shape == (PHOTO_SIZE, PHOTO_SIZE, 3)
        assert view["depth"].shape == view["mask"].shape == (PHOTO_SIZE, PHOTO_SIZE)
        assert set(np.unique(view["mask"])) <= {0, 1, 2}
        assert (view["mask"] == 1).any() and (view["mask"] == 2).any()


@pytest.mark.slow
def test_photo_is_not_flat(photos):
    photo = load_view(photos, 0)["photo"].astype(float)
    assert photo.std() > 10.0


@pytest.mark.slow
def test_depth_is_positive_on_the_tree_and_zero_in_the_sky_and_the_ground_is_seen(photos):
    view = load_view(photos, 0)
    assert (view["depth"][view["mask"] > 0] > 0).all()
    assert (view["depth"][0] == 0).all()        # the top row looks into the sky
    assert (view["depth"][-1] > 0).all()        # the bottom row sees the ground plane


@pytest.mark.slow
def test_cameras_json_records_the_cameras_in_our_convention(photos):
    data = json.loads(photos.cameras_json.read_text())
    assert data["convention"] == "opencv" and len(data["views"]) == 2
    for record, camera in zip(data["views"], photos.cameras):
        again = Camera.from_dict(record)
        np.testing.assert_allclose(again.K, camera.K)
        np.testing.assert_allclose(again.world_to_camera, camera.world_to_camera)
        assert (photos.cameras_json.parent / record["image"]).is_file()
        assert record["depth_scale"] > 0


def test_unknown_photo_setting_fails_with_the_workers_message(tree_glb, tmp_path):
    with pytest.raises(BlenderError, match="no_such_setting"):
        render_photos(tree_glb, [_camera()], tmp_path, samples=1, no_such_setting=1)


def test_unknown_job_kind_fails_naming_the_known_kinds(tmp_path):
    with pytest.raises(BlenderError, match="photos"):
        run_job("no_such_kind", {}, tmp_path)


def test_missing_glb_file_is_rejected_before_blender_starts(tmp_path):
    with pytest.raises(BlenderError, match="does not exist"):
        render_photos(tmp_path / "missing.glb", [_camera()], tmp_path)


def test_several_jobs_run_in_one_blender_process(tree_glb, tmp_path):
    glb = tmp_path / "tree.glb"
    glb.write_bytes(tree_glb)
    results = run_jobs([("info", {"glb": str(glb)}, tmp_path / "a"), ("info", {"glb": str(glb)}, tmp_path / "b")])
    assert len(results) == 2 and results[0] == results[1]
    assert (tmp_path / "a" / "result.json").is_file() and (tmp_path / "b" / "result.json").is_file()
