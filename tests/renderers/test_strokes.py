"""Main-branch rule, the shared palette and the trunk stroke rasteriser."""
from __future__ import annotations

import numpy as np

from renderers.camera import look_at, Camera
from renderers.strokes import MAIN_MIN_LENGTH_SHARE, PALETTE, main_branches, rasterize_strokes, trunk_strokes


def test_palette_has_twelve_distinct_colours_and_is_read_only():
    assert PALETTE.shape == (12, 3) and PALETTE.dtype == np.uint8
    assert len({tuple(c) for c in PALETTE}) == 12
    assert not PALETTE.flags.writeable


def test_main_branches_start_with_the_trunk_and_follow_the_rule(tree):
    _, skeleton = tree
    branches = main_branches(skeleton)
    assert branches[0] == skeleton.branch_id[0]
    length = np.bincount(skeleton.branch_id, weights=skeleton.segment_lengths)
    starts = skeleton.branch_starts
    assert np.all(skeleton.order[starts[branches]] <= 2)
    assert np.all(length[branches[1:]] > MAIN_MIN_LENGTH_SHARE * skeleton.height)
    assert len(branches) > 1


def test_main_branches_come_in_bfs_order(tree):
    _, skeleton = tree
    branches = main_branches(skeleton)
    rank = {int(b): i for i, b in enumerate(branches)}
    starts = skeleton.branch_starts
    for b in branches[1:]:
        parent_branch = int(skeleton.branch_id[skeleton.parent[starts[b]]])
        assert rank[parent_branch] < rank[int(b)]
    orders = skeleton.order[starts[branches]]
    assert np.all(np.diff(orders.astype(int)) >= 0)  # levels never go back up


def test_palette_is_stable_across_trees(all_outputs, view_renderer, other_tree):
    mesh, skeleton = other_tree
    other = view_renderer.render(mesh, skeleton, "two-view", ["trunk_strokes"], np.random.default_rng(0))[0]
    for strokes in (all_outputs["two-view"][0].images["trunk_strokes"], other.images["trunk_strokes"]):
        colours = {tuple(c) for c in strokes.reshape(-1, 3)} - {(255, 255, 255)}
        assert colours <= {tuple(c) for c in PALETTE}
        # The trunk (bottom centre of the frame) always wears the first colour.
        bottom = strokes[int(strokes.shape[0] * 0.85)]
        assert tuple(PALETTE[0]) in {tuple(c) for c in bottom}


def test_trunk_depth_marks_exactly_the_strokes(all_outputs):
    images = all_outputs["tsn4"][2].images
    drawn = np.any(images["trunk_strokes"] != 255, axis=-1)
    depth = images["trunk_depth"]
    np.testing.assert_array_equal(depth < 1, drawn)
    assert depth.dtype == np.float32 and depth.min() >= 0


def test_strokes_are_four_pixels_wide():
    camera = Camera(64, 64, [[10.0, 0, 31.5], [0, 10.0, 31.5], [0, 0, 1]], look_at([0, -10, 0], [0, 0, 0]),
                    "orthographic", 1.0, 20.0, 3.2, 3.2)
    labels, _ = rasterize_strokes(camera, np.array([[0.0, 0, -2]]), np.array([[0.0, 0, 2]]), np.array([0]))
    widths = (labels[20:44] >= 0).sum(axis=1)
    assert np.all((widths >= 3) & (widths <= 4)) and widths.mean() >= 3.5


def test_nearer_stroke_wins_where_strokes_cross():
    camera = Camera(64, 64, [[10.0, 0, 31.5], [0, 10.0, 31.5], [0, 0, 1]], look_at([0, -10, 0], [0, 0, 0]),
                    "orthographic", 1.0, 20.0, 3.2, 3.2)
    starts = np.array([[-2.0, 1.0, 0], [0, -1.0, -2]])   # label 0 far (y = 1), label 1 near (y = -1)
    ends = np.array([[2.0, 1.0, 0], [0, -1.0, 2]])
    labels, depth = rasterize_strokes(camera, starts, ends, np.array([0, 1]))
    assert labels[31, 31] == 1 and depth[31, 31] == np.float32(9.0)
    assert labels[31, 10] == 0 and depth[31, 10] == np.float32(11.0)


def test_trunk_strokes_are_deterministic(tree, all_outputs):
    _, skeleton = tree
    view = all_outputs["tsn4"][0]
    again = trunk_strokes(view.camera, skeleton)
    np.testing.assert_array_equal(again[0], view.images["trunk_strokes"])
    np.testing.assert_array_equal(again[1], view.images["trunk_depth"])


def test_a_tree_and_its_mirror_through_the_image_plane_draw_the_same_strokes_at_depth_one_minus(tree, all_outputs):
    """Why a network cannot tell the depth of an orthographic stroke drawing (docs/training.md): mirrored through
    the plane of the view's box centre, a tree draws the same pixels in the same camera, at trunk depth 1 - d; only
    where strokes overlap does the colour on top change (the nearer stroke wins), the one depth cue left. A tree's
    mirror is about as likely a tree, so the best guess of a stroke pixel's depth is close to 0.5."""
    from species.skeleton import Skeleton

    mesh, skeleton = tree
    view = all_outputs["two-view"][0]
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    to_camera = view.camera.world_to_camera[:3, :3]
    axis = to_camera[2]  # the viewing direction in world axes
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    assert np.abs(axis).max() > 1 - 1e-9  # the front view looks along a world axis: the box mirrors onto itself
    offset = (skeleton.positions - centre) @ axis
    mirrored = Skeleton(skeleton.positions - 2 * offset[:, None] * axis[None, :], skeleton.parent, skeleton.radius,
                        skeleton.order)
    strokes, depth = trunk_strokes(view.camera, mirrored)
    drawn = view.images["trunk_depth"] < 1
    np.testing.assert_array_equal(depth < 1, drawn)
    same = np.all(strokes == view.images["trunk_strokes"], axis=-1) & drawn
    assert same.sum() >= 0.6 * drawn.sum()  # 32 branches in 160 px: a quarter of the stroke pixels overlap
    residual = np.abs(depth[same] - (1.0 - view.images["trunk_depth"][same]))
    assert np.median(residual) < 0.01 and np.quantile(residual, 0.8) < 0.02
