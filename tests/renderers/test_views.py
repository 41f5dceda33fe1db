"""ViewRenderer: the output contract, determinism, renderer reuse and rejection of bad names."""
from __future__ import annotations

import json

import numpy as np
import pytest

from renderers import (DEFAULT_OUTPUTS, FLOAT_OUTPUTS, LABEL_MAPS, METRIC_MAPS, OUTPUTS, CameraError, Output,
                       OutputError, viewable, write_contact_sheet)
from renderers.camera import perspective_camera
from species.tree_mesh import MeshPart, TreeMesh

CONTRACT = {
    "depth": ((), np.float32), "depth01": ((), np.float32), "mask": ((), np.uint8), "order": ((), np.uint8),
    "normals": ((3,), np.uint8), "silhouette": ((3,), np.float32), "trunk_strokes": ((3,), np.uint8),
    "trunk_depth": ((), np.float32), "sketch_tsn": ((), np.uint8), "sketch_edges": ((), np.uint8),
    "sketch_strokes": ((), np.uint8), "sketch_strokes_brush": ((), np.uint8), "sketch_crown": ((), np.uint8),
    "sketch_hand": ((), np.uint8),
}


def test_every_contract_output_has_its_shape_and_dtype(all_outputs):
    assert set(CONTRACT) <= set(OUTPUTS) and set(DEFAULT_OUTPUTS) <= set(OUTPUTS)
    for view in all_outputs["tsn4"]:
        h, w = view.camera.height, view.camera.width
        for name, (tail, dtype) in CONTRACT.items():
            assert view.images[name].shape == (h, w) + tail, name
            assert view.images[name].dtype == dtype, name


def test_every_output_comes_back_as_the_dtype_its_entry_declares(all_outputs):
    for view in all_outputs["tsn4"]:
        for name, output in OUTPUTS.items():
            assert view.images[name].dtype == output.dtype, name
            if output.metric:  # metres, 0 = background
                assert view.images[name].min() == 0 and view.images[name].max() > 0, name
            elif output.is_float:
                assert 0 <= view.images[name].min() and view.images[name].max() <= 1, name


def test_float_and_metric_names_follow_the_entries_even_one_registered_later(monkeypatch):
    assert set(FLOAT_OUTPUTS) == {"depth", "depth01", "silhouette", "silhouette_envelope", "depth_back", "trunk_depth"}
    assert set(METRIC_MAPS) == {"depth", "depth_back"} and "mask" not in FLOAT_OUTPUTS
    monkeypatch.setitem(OUTPUTS, "test_metres", Output(lambda frame: frame.visible[0], np.float32, metric=True))
    assert "test_metres" in FLOAT_OUTPUTS and "test_metres" in METRIC_MAPS and len(METRIC_MAPS) == 3


def test_label_maps_follow_the_entries_and_the_contact_sheet_spreads_them(monkeypatch):
    assert set(LABEL_MAPS) == {"mask", "order", "photo_mask"}
    monkeypatch.setitem(OUTPUTS, "test_classes", Output(lambda frame: frame.visible[1], np.uint8, label=True))
    labels = np.array([[0, 1, 2]], np.uint8)
    assert "test_classes" in LABEL_MAPS and "test_classes" not in FLOAT_OUTPUTS
    assert viewable("test_classes", labels)[0, :, 0].tolist() == [0, 80, 160]  # spread over the grey range
    assert viewable("sketch_tsn", labels)[0, :, 0].tolist() == [0, 1, 2]  # grey levels as they are


def test_maps_with_a_mask_channel_show_black_outside_the_tree_in_a_contact_sheet(monkeypatch, all_outputs):
    for name in ("silhouette", "silhouette_envelope"):
        image = all_outputs["tsn4"][0].images[name]
        outside = image[..., 2] == 0
        assert outside.any() and (image[outside][:, 0] == 1.0).all()  # stored: far depth there, a red picture
        shown = viewable(name, image)
        assert (shown[outside] == 0).all() and (shown[~outside] == viewable("sketch_tsn", image)[~outside]).all()
    monkeypatch.setitem(OUTPUTS, "test_masked", Output(lambda frame: frame.visible[0], np.float32, mask_channel=0))
    pair = np.array([[[0.0, 0.7, 0.7], [1.0, 0.7, 0.7]]], np.float32)
    assert viewable("test_masked", pair)[0, :, 1].tolist() == [0, 178]  # a registered output follows its entry


@pytest.mark.parametrize("dtype, metric, named", [(np.float64, False, "dtype float64"),
                                                   (np.uint8, True, "metric output of dtype uint8")])
def test_an_entry_of_another_dtype_or_a_metric_uint8_one_is_refused(dtype, metric, named):
    with pytest.raises(OutputError, match=named):
        Output(lambda frame: frame.visible[0], dtype, metric=metric)


def test_a_label_entry_of_float_dtype_is_refused():
    with pytest.raises(OutputError, match="label output of dtype float32"):
        Output(lambda frame: frame.visible[0], np.float32, label=True)


def test_views_carry_index_name_and_json_camera(all_outputs):
    views = all_outputs["tsn4"]
    assert [v.index for v in views] == [0, 1, 2, 3]
    assert [v.name for v in views] == ["front", "right", "back", "left"]
    data = json.loads(json.dumps(views[0].camera.to_dict()))
    assert data["projection"] == "perspective" and len(data["world_to_camera"]) == 4


def test_same_inputs_give_identical_arrays(view_renderer, tree, all_outputs):
    mesh, skeleton = tree
    again = view_renderer.render(mesh, skeleton, "tsn4", list(OUTPUTS), np.random.default_rng(3))
    for first, second in zip(all_outputs["tsn4"], again):
        for name in OUTPUTS:
            np.testing.assert_array_equal(first.images[name], second.images[name], err_msg=name)


def test_renderer_follows_a_size_change_and_back(view_renderer, tree):
    mesh, skeleton = tree
    size = view_renderer.size
    try:
        view_renderer.size = 96
        small = view_renderer.render(mesh, skeleton, "two-view", ["mask"], np.random.default_rng(0))[0]
    finally:
        view_renderer.size = size
    big = view_renderer.render(mesh, skeleton, "two-view", ["mask"], np.random.default_rng(0))[0]
    assert small.images["mask"].shape == (96, 96) and big.images["mask"].shape == (size, size)
    assert abs((small.images["mask"] > 0).mean() - (big.images["mask"] > 0).mean()) < 0.02


def test_unknown_output_is_rejected_with_the_allowed_names(view_renderer, tree):
    mesh, skeleton = tree
    with pytest.raises(OutputError, match="sketch_tsn"):
        view_renderer.render(mesh, skeleton, "tsn4", ["depth", "sketch_fancy"], np.random.default_rng(0))


def test_unknown_rig_is_rejected(view_renderer, tree):
    mesh, skeleton = tree
    with pytest.raises(CameraError, match="two-view"):
        view_renderer.render(mesh, skeleton, "six-view", ["depth"], np.random.default_rng(0))


def test_contact_sheet_is_a_grid_of_rows_and_columns(tmp_path, all_outputs):
    from PIL import Image

    from renderers.contact_sheet import contact_sheet

    rows = [(rig, [(name, views[0].images[name]) for name in DEFAULT_OUTPUTS]) for rig, views in all_outputs.items()]
    path = write_contact_sheet(tmp_path / "sheet.png", rows, cell=64)
    sheet = np.asarray(Image.open(path))
    assert sheet.shape[0] > 2 * 64 and sheet.shape[1] >= len(DEFAULT_OUTPUTS) * 64
    np.testing.assert_array_equal(sheet, contact_sheet(rows, cell=64))  # the file holds the grid's RGB pixels


def test_jittered_rig_repeats_with_the_rng_and_moves_the_cameras(view_renderer, tree):
    mesh, skeleton = tree
    a, b = (view_renderer.render(mesh, skeleton, "tsn4:jitter", ["mask"], np.random.default_rng(9)) for _ in "ab")
    plain = view_renderer.render(mesh, skeleton, "tsn4", ["mask"], np.random.default_rng(9))
    np.testing.assert_array_equal(a[1].images["mask"], b[1].images["mask"])
    assert not np.allclose(a[1].camera.world_to_camera, plain[1].camera.world_to_camera)


def test_rendering_a_plain_rigs_cameras_gives_the_rigs_views_byte_for_byte(view_renderer, tree, all_outputs):
    mesh, skeleton = tree
    cameras = view_renderer.cameras(mesh, "two-view", np.random.default_rng(3))
    views = view_renderer.render_cameras(mesh, skeleton, cameras, list(OUTPUTS), np.random.default_rng(3))
    assert [v.name for v in views] == ["front", "side"] and [v.index for v in views] == [0, 1]
    for first, second in zip(all_outputs["two-view"], views):
        for name in OUTPUTS:
            np.testing.assert_array_equal(first.images[name], second.images[name], err_msg=name)


def test_given_cameras_render_at_their_own_size_and_order(view_renderer, tree):
    mesh, skeleton = tree
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    unseen = perspective_camera(points, 45.0, 30.0, 48, name="unseen")
    wide = view_renderer.cameras(mesh, "tsn4", np.random.default_rng(0))[2]
    views = view_renderer.render_cameras(mesh, skeleton, [unseen, wide], ["mask", "depth"], np.random.default_rng(0))
    assert [v.name for v in views] == ["unseen", "back"]
    assert views[0].images["mask"].shape == (48, 48) and views[0].camera is unseen
    assert views[1].images["depth"].shape == (view_renderer.size, view_renderer.size)
    assert 0.02 < (views[0].images["mask"] > 0).mean() < 0.9


def test_silhouette_masks_are_the_mask_output_above_zero(view_renderer, tree, all_outputs):
    mesh, _ = tree
    views = all_outputs["tsn4"]
    masks = view_renderer.silhouette_masks(mesh, [v.camera for v in views])
    assert masks.shape == (4, view_renderer.size, view_renderer.size) and masks.dtype == bool
    for view, mask in zip(views, masks):
        np.testing.assert_array_equal(mask, view.images["mask"] > 0)


def test_an_empty_tree_covers_no_pixel(view_renderer, tree):
    mesh, _ = tree
    cameras = view_renderer.cameras(mesh, "two-view", np.random.default_rng(0))
    empty = TreeMesh(MeshPart.empty(), MeshPart.empty(), name="empty")
    masks = view_renderer.silhouette_masks(empty, cameras)
    assert masks.shape == (2, view_renderer.size, view_renderer.size) and not masks.any()


def test_shared_two_view_silhouettes_span_the_same_rows(view_renderer, other_tree):
    mesh, _ = other_tree
    wide = TreeMesh(*(MeshPart(p.vertices * np.float32([3, 1, 1]), p.faces, p.normals, p.uvs, p.attributes)
                      for p in (mesh.bark, mesh.leaves)), name="wide")
    cameras = view_renderer.cameras(wide, "two-view:shared", np.random.default_rng(0))
    rows = view_renderer.silhouette_masks(wide, cameras).any(axis=2)  # (2, H): rows the tree covers per view
    spans = [np.flatnonzero(r)[[0, -1]] for r in rows]
    assert np.abs(spans[0] - spans[1]).max() <= 1


@pytest.mark.parametrize("cameras", ["two-view", [], ["front"]])
def test_render_cameras_rejects_what_is_not_a_list_of_cameras(view_renderer, tree, cameras):
    mesh, skeleton = tree
    with pytest.raises(CameraError, match="Camera"):
        view_renderer.render_cameras(mesh, skeleton, cameras, ["mask"], np.random.default_rng(0))


def test_silhouette_masks_reject_cameras_of_different_sizes(view_renderer, tree):
    mesh, _ = tree
    big = view_renderer.cameras(mesh, "two-view", np.random.default_rng(0))[0]
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    with pytest.raises(CameraError, match="one size"):
        view_renderer.silhouette_masks(mesh, [big, perspective_camera(points, 0.0, 0.0, 32)])
