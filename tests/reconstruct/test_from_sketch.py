"""Depth-guided growth from one sketch: the steps on known answers, and end to end on ground-truth maps of a
generated tree standing in for the networks' outputs."""
from __future__ import annotations

import numpy as np
import pytest

import species
from renderers import PALETTE, ViewRenderer
from renderers.camera import orthographic_camera, perspective_camera
from reconstruct.from_sketch import CameraCrown, SketchError, backproject, denoise_depth, from_maps, geodesic_field
from reconstruct.trunk_tracing import TRACE_STEP_PX, trace_trunk
from species.errors import TreefarmError

SIZE = 128
BOX = np.array([[-2.0, -2.0, 0.0], [2.0, 2.0, 6.0]])


def _corners(box: np.ndarray) -> np.ndarray:
    return np.array([[x, y, z] for x in box[:, 0] for y in box[:, 1] for z in box[:, 2]])


def _cameras(size: int):
    points = _corners(BOX)
    return [orthographic_camera(points, 0.0, 0.0, size), perspective_camera(points, 30.0, 10.0, size)]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    union = (a | b).sum()
    return float((a & b).sum() / union) if union else 0.0


# ------------------------------------------------------------------------------------------------ steps
@pytest.mark.parametrize("camera", _cameras(48), ids=["orthographic", "perspective"])
def test_backprojection_of_a_plane_recovers_the_plane(camera):
    normal = np.array([0.3, -1.0, 0.2]) / np.linalg.norm([0.3, -1.0, 0.2])
    point = np.array([0.1, 0.2, 3.0])
    v, u = np.mgrid[0:camera.height, 0:camera.width]
    pixels = np.stack([u.ravel(), v.ravel()], axis=1)
    # Points on each pixel's ray are linear in camera depth: p(z) = a + z b; solve normal . (p - point) = 0.
    a = camera.unproject(pixels, np.zeros(len(pixels)))
    b = camera.unproject(pixels, np.ones(len(pixels))) - a
    depth = ((point - a) @ normal) / (b @ normal)
    mask = ((depth > camera.near) & (depth < camera.far)).reshape(v.shape)
    depth01 = camera.depth01(np.where(mask.ravel(), depth, 0.0).reshape(v.shape))
    points = backproject(depth01, mask, camera)
    assert points.shape == (mask.sum(), 3) and mask.mean() > 0.5
    span = camera.far - camera.near
    np.testing.assert_allclose((points - point) @ normal, 0.0, atol=1e-5 * span)
    back, _ = camera.project(points)
    np.testing.assert_allclose(back, pixels[mask.ravel()], atol=1e-4)


def _disc_mask(size=48, radius=16):
    v, u = np.mgrid[0:size, 0:size]
    return (u - size / 2) ** 2 + (v - size / 2) ** 2 <= radius ** 2, u


def test_denoise_leaves_a_smooth_map_unchanged():
    mask, u = _disc_mask()
    depth = np.where(mask, 0.3 + 0.004 * u, 1.0)
    cleaned, kept = denoise_depth(depth, mask)
    np.testing.assert_array_equal(cleaned, depth)
    np.testing.assert_array_equal(kept, mask)


def test_denoise_replaces_an_injected_boundary_spike_by_its_neighbours():
    mask, u = _disc_mask()
    smooth = np.where(mask, 0.3 + 0.004 * u, 1.0)
    row, col = 24, int(np.flatnonzero(mask[24])[0])  # the leftmost pixel of the middle row: on the boundary
    spiked = smooth.copy()
    spiked[row, col] += 0.45
    cleaned, kept = denoise_depth(np.stack([spiked, smooth], axis=-1), mask)
    assert abs(cleaned[row, col, 0] - smooth[row, col]) < 0.01
    assert kept[row, col]
    interior = mask & (np.hypot(np.arange(48)[:, None] - row, np.arange(48)[None] - col) > 3)
    np.testing.assert_array_equal(cleaned[..., 0][interior], smooth[interior])
    np.testing.assert_array_equal(cleaned[..., 1], smooth)  # each channel on its own


def _draw(image: np.ndarray, start, end, colour, width=4.0) -> None:
    """A `width` px wide segment from start to end (u, v) in `colour`, drawn into image (H, W, 3)."""
    v, u = np.mgrid[0:image.shape[0], 0:image.shape[1]]
    p, a, b = np.stack([u, v], -1).astype(float), np.asarray(start, float), np.asarray(end, float)
    t = np.clip(((p - a) @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
    near = np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1) < width / 2
    image[near] = colour


def _y_strokes(size=64, hand_drawn=False, rng=None):
    """A Y: PALETTE[0] up the trunk and on along the left arm, PALETTE[3] from the fork up the right arm."""
    strokes = np.full((size, size, 3), 255, np.uint8)
    fork = (32, 32)
    trunk, right = PALETTE[0].astype(float), PALETTE[3].astype(float)
    if hand_drawn:  # lighter, shifted and noisy colours, a wider pen: a scanned felt-tip drawing
        trunk, right = 0.7 * trunk + 0.3 * np.array([255, 120, 90]), 0.75 * right + 60
    _draw(strokes, (32, 60), fork, trunk, 6.0 if hand_drawn else 4.0)
    _draw(strokes, fork, (18, 8), trunk, 6.0 if hand_drawn else 4.0)
    _draw(strokes, fork, (48, 8), right, 6.0 if hand_drawn else 4.0)
    if hand_drawn:
        noise = rng.normal(0, 12, strokes.shape)
        strokes = np.clip(strokes + noise, 0, 255).astype(np.uint8)
    depth = np.where((strokes < 200).any(axis=2), 0.5, 1.0).astype(np.float32)
    return strokes, depth, fork


@pytest.mark.parametrize("hand_drawn", [False, True], ids=["palette", "hand-drawn"])
def test_trace_of_a_drawn_y_gives_two_branches_meeting_at_the_fork(hand_drawn):
    strokes, depth, fork = _y_strokes(hand_drawn=hand_drawn, rng=np.random.default_rng(0))
    camera = orthographic_camera(_corners(BOX), 0.0, 0.0, 64)
    main = trace_trunk(strokes, depth, camera)
    assert main.n_branches == 2
    pixels, _ = camera.project(main.positions)
    assert pixels[0, 1] > 55  # the root is the lowest point of the strokes
    second = main.branch_paths[1]
    junction = pixels[second[0]]
    assert np.linalg.norm(junction - fork) <= 1.5 * TRACE_STEP_PX  # one node step away at most
    assert main.branch_id[second[0]] == 0 and main.order[second[1]] == 1  # it grows from the trunk branch
    assert np.all(pixels[second[1:], 0] > fork[0]) and pixels[second[-1], 1] < 14  # and runs up the right arm
    np.testing.assert_allclose(camera.depth01(camera.project(main.positions)[1]), 0.5, atol=1e-3)


@pytest.mark.parametrize("gap", [5, 9])
def test_a_branch_whose_base_is_hidden_is_traced_from_the_nearest_trunk_node(gap):
    """A branch seen only from a few pixels past its parent (its base hidden behind another stroke) is not
    reached by the probes; tracing goes on from the untraced stroke nearest the traced ones."""
    strokes = np.full((64, 64, 3), 255, np.uint8)
    _draw(strokes, (32, 60), (32, 4), PALETTE[0].astype(float), 4.0)
    _draw(strokes, (34 + gap, 36), (56, 12), PALETTE[3].astype(float), 4.0)
    depth = np.where((strokes < 200).any(axis=2), 0.5, 1.0).astype(np.float32)
    camera = orthographic_camera(_corners(BOX), 0.0, 0.0, 64)
    main = trace_trunk(strokes, depth, camera)
    assert main.n_branches == 2
    pixels, _ = camera.project(main.positions)
    branch = main.branch_paths[1]
    assert abs(pixels[branch[0], 0] - 32) <= 1 and abs(pixels[branch[0], 1] - 36) <= TRACE_STEP_PX  # on the trunk
    assert np.linalg.norm(pixels[branch[-1]] - (56, 12)) <= TRACE_STEP_PX  # and out to the branch's end


def test_camera_crown_holds_the_points_between_front_and_back_depth():
    camera = _cameras(32)[1]
    mask = np.zeros((32, 32), bool)
    mask[8:24, 8:24] = True
    crown = CameraCrown(np.full((32, 32), 0.4), np.full((32, 32), 0.6), mask, camera, origin=(0, 0, 1), scale=2.0)
    span = camera.far - camera.near
    along = camera.unproject(np.array([[16.0, 16.0]] * 3), camera.near + np.array([0.3, 0.5, 0.7]) * span)
    outside = camera.unproject(np.array([[2.0, 2.0]]), [camera.near + 0.5 * span])
    points = (np.concatenate([along, outside]) - [0, 0, 1]) * 2.0  # into the crown's output frame
    np.testing.assert_array_equal(crown.contains(points), [False, True, False, False])


def test_geodesic_field_points_up_a_vertical_strip_from_its_base():
    mask = np.zeros((64, 16), bool)
    mask[4:60, 5:12] = True
    directions, distance = geodesic_field(mask, (8, 59), bin_px=8.0)
    assert np.isinf(distance[0, 0]) and distance[59, 8] == 0
    assert np.all(directions[mask][:, 1] > 0.7)  # image-plane (x right, z up): up the strip
    below_top = mask & (np.arange(64) > 4)[:, None]  # the top row's corners are clusters of their own
    np.testing.assert_allclose(directions[below_top], [[0.0, 1.0]] * below_top.sum(), atol=0.02)


# ------------------------------------------------------------------------------------------------ end to end
@pytest.fixture(scope="module")
def renderer():
    renderer = ViewRenderer(SIZE)
    yield renderer
    renderer.close()


def _tree(preset: str, seed: int):
    params = species.sample(preset, np.random.default_rng(seed))
    skeleton = species.grow(params, np.random.default_rng(params["seed"]))
    return skeleton, species.build_mesh(skeleton, params)


@pytest.fixture(scope="module")
def sketch(renderer):
    """Ground truth of a generated tree in the front view of the two-view rig, as the networks would predict it."""
    skeleton, mesh = _tree("sc_round_maple", 5)
    view = renderer.render(mesh, skeleton, "two-view", ["silhouette", "trunk_strokes", "trunk_depth", "mask"],
                           np.random.default_rng(0))[0]
    return skeleton, view


def _reconstruct(sketch, seed: int, **kwargs):
    skeleton, view = sketch
    images = view.images
    return from_maps(images["silhouette"], images["trunk_depth"], images["trunk_strokes"], view.camera,
                       height=kwargs.pop("height", skeleton.height), rng=np.random.default_rng(seed), **kwargs)


@pytest.fixture(scope="module")
def result(sketch):
    return _reconstruct(sketch, 1)


def test_grown_tree_fills_the_input_silhouette_far_better_than_an_empty_or_a_random_tree(renderer, sketch, result):
    _, view = sketch
    truth = view.images["mask"] > 0
    grown = renderer.silhouette_masks(result.mesh, [view.camera])[0]
    other = renderer.silhouette_masks(_tree("sc_columnar_poplar", 9)[1], [view.camera])[0]
    iou, random_iou, empty_iou = _iou(grown, truth), _iou(other, truth), _iou(np.zeros_like(truth), truth)
    assert iou > 0.35 and iou > random_iou + 0.1 and empty_iou == 0.0, (iou, random_iou)


def test_tree_stands_on_the_traced_trunk_base_at_the_asked_height(sketch, result):
    truth, _ = sketch
    tree = result.skeleton
    np.testing.assert_allclose(tree.positions[0], 0.0, atol=1e-6)
    assert abs(tree.height - truth.height) < 0.05 * truth.height
    assert result.params["height"] == truth.height and result.params["generator"] == "colonization"
    main = result.maps["main_skeleton"]
    np.testing.assert_array_equal(tree.positions[:len(main)], main)  # the guide's nodes come first, as given


def test_strokes_above_the_crown_set_the_trees_top(sketch):
    """A bare leader drawn above the crown (here: the crown's top third cut from the silhouette) is the tree's
    top: the traced main skeleton reaches the asked height, not a taller one scaled to the crown alone."""
    skeleton, view = sketch
    silhouette = view.images["silhouette"].copy()
    rows = np.flatnonzero((silhouette[..., 2] >= 0.5).any(axis=1))
    silhouette[: rows[0] + (rows[-1] - rows[0]) // 3, :, 2] = 0.0
    cut = from_maps(silhouette, view.images["trunk_depth"], view.images["trunk_strokes"], view.camera,
                    height=skeleton.height, rng=np.random.default_rng(1))
    top = cut.maps["main_skeleton"][:, 2].max()
    assert skeleton.height * 0.9 <= top <= skeleton.height * 1.01


def test_height_sets_the_metric_scale_and_defaults_to_the_presets_draw(sketch, result):
    smaller = _reconstruct(sketch, 1, height=result.params["height"] / 2)
    assert abs(smaller.maps["main_skeleton"][:, 2].max() * 2 - result.maps["main_skeleton"][:, 2].max()) < 1e-4
    drawn = _reconstruct(sketch, 1, height=None)
    assert 9.0 <= drawn.params["height"] <= 15.0  # sc_round_maple's range
    assert abs(drawn.skeleton.height - drawn.params["height"]) < 0.05 * drawn.params["height"]


def test_report_has_stage_timings_and_intermediate_maps(result):
    assert {"denoise", "trunk", "crown", "field", "growth", "mesh", "total"} <= set(result.timings)
    assert result.timings["total"] >= sum(v for k, v in result.timings.items() if k != "total") * 0.99
    for name in ("front", "back", "crown_mask", "geodesic", "directions"):
        assert result.maps[name].shape[:2] == (SIZE, SIZE), name
    assert np.all(result.maps["back"] >= result.maps["front"])


def test_same_seed_gives_the_same_bytes_and_another_seed_another_tree(sketch, result):
    again = _reconstruct(sketch, 1)
    assert again.mesh.to_glb() == result.mesh.to_glb()
    np.testing.assert_array_equal(again.skeleton.positions, result.skeleton.positions)
    assert _reconstruct(sketch, 2).mesh.to_glb() != result.mesh.to_glb()


# ------------------------------------------------------------------------------------------------ errors
def _one_line_error(call, match: str):
    with pytest.raises(SketchError, match=match) as caught:
        call()
    assert isinstance(caught.value, TreefarmError) and "\n" not in str(caught.value)


def test_blank_silhouette_is_rejected(sketch):
    _, view = sketch
    blank = np.zeros_like(view.images["silhouette"])
    _one_line_error(lambda: from_maps(blank, view.images["trunk_depth"], view.images["trunk_strokes"],
                                        view.camera, rng=np.random.default_rng(0)), "blank")


def test_strokes_without_a_trunk_are_rejected(sketch):
    _, view = sketch
    white = np.full_like(view.images["trunk_strokes"], 255)
    white[10:20, 10:20] = 0  # black pencil is not a trunk stroke
    _one_line_error(lambda: from_maps(view.images["silhouette"], view.images["trunk_depth"], white,
                                        view.camera, rng=np.random.default_rng(0)), "no trunk stroke")


def test_wrong_channel_counts_sizes_and_species_are_rejected(sketch):
    _, view = sketch
    images, camera = view.images, view.camera
    _one_line_error(lambda: from_maps(images["silhouette"][..., :2], images["trunk_depth"],
                                        images["trunk_strokes"], camera, rng=np.random.default_rng(0)),
                    r"\(H, W, 3\)")
    _one_line_error(lambda: from_maps(images["silhouette"], images["trunk_depth"],
                                        images["trunk_strokes"][..., :2], camera, rng=np.random.default_rng(0)),
                    "strokes")
    _one_line_error(lambda: from_maps(images["silhouette"][:64, :64], images["trunk_depth"][:64, :64],
                                        images["trunk_strokes"][:64, :64], camera, rng=np.random.default_rng(0)),
                    "camera")
    _one_line_error(lambda: from_maps(images["silhouette"], images["trunk_depth"], images["trunk_strokes"],
                                        camera, species="black_oak", rng=np.random.default_rng(0)),
                    "colonization")


def test_through_the_shipped_networks_the_grown_crown_covers_the_drawn_one(renderer):
    """End to end as a user runs it: the edge sketch and trunk strokes of a tree the networks never saw, the
    shipped silhouette and trunk networks, growth; the grown crown seen in the drawing's view against the drawn."""
    from reconstruct import from_sketch
    from renderers.silhouette_metric import closed_silhouette

    skeleton, mesh = _tree("sc_round_maple", 17)
    renderer.size = 256  # the networks' size; the module's renderer follows
    try:
        view = renderer.render(mesh, skeleton, "two-view", ["sketch_edges", "trunk_strokes", "mask"],
                               np.random.default_rng(0))[0]
        result = from_sketch(view.images["sketch_edges"], view.images["trunk_strokes"], height=skeleton.height,
                             rng=np.random.default_rng(1))
        grown, other = renderer.silhouette_masks(result.mesh, [view.camera])[0], renderer.silhouette_masks(
            _tree("sc_columnar_poplar", 9)[1], [view.camera])[0]
    finally:
        renderer.size = SIZE
    drawn = closed_silhouette(view.images["mask"] > 0, 3)
    iou, other_iou = (_iou(closed_silhouette(m, 3), drawn) for m in (grown, other))
    assert iou > 0.7 and iou > other_iou + 0.3, (iou, other_iou)  # thresholds well clear of what this tree gives
    assert abs(result.skeleton.height - skeleton.height) < 0.1 * skeleton.height
