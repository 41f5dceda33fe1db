"""The octahedral impostor: the hemi-octahedral mapping and its frame weights (round trips, known points), the
atlas of a hand-built tree (size, which side each frame sees it from, limits, determinism), its quad and layout,
and the silhouette it shows against the tree's own."""
from __future__ import annotations

import json

import numpy as np
import pytest

from renderers.camera import view_direction
from renderers.gl_coverage import CoverageRenderer
from renderers.impostor import ImpostorError
from renderers.silhouette_metric import closed_silhouette, silhouette_iou, switch_camera
from renderers.octahedral_impostor import (MAX_ATLAS_PX, between_frame_azimuths, frame_axes, frame_directions,
                                           frame_extents, frame_weights, octahedral_decode, octahedral_encode,
                                           render_octahedral_impostor)
from species.tree_mesh import MeshPart, TreeMesh

FRAMES = 5  # odd: one frame looks straight down
TILE = 32


def _box(lo, hi) -> MeshPart:
    """A closed box (12 triangles, wound outward) between corners lo and hi (metres, Z up)."""
    x, y, z = np.array([lo, hi], np.float64).T
    vertices = np.array([[x[i], y[j], z[k]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1], [2, 3, 7], [2, 7, 6],
                      [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    normals = vertices - vertices.mean(axis=0)
    return MeshPart(vertices, faces, normals / np.linalg.norm(normals, axis=1, keepdims=True),
                    np.zeros((8, 2)))


def _marked_tree() -> TreeMesh:
    """A 4 m post on the origin, half a metre thick, with a 0.8 m block on its +X side, 1.5 m out and 2.5 m up
    (thick enough to keep their width through two samplings, the frame's and the screen's)."""
    post, block = _box([-0.25, -0.25, 0.0], [0.25, 0.25, 4.0]), _box([1.1, -0.4, 2.1], [1.9, 0.4, 2.9])
    bark = MeshPart(np.concatenate([post.vertices, block.vertices]), np.concatenate([post.faces, block.faces + 8]),
                    np.concatenate([post.normals, block.normals]), np.zeros((16, 2)))
    return TreeMesh(bark=bark, leaves=MeshPart.empty(), name="marked")


@pytest.fixture(scope="module")
def renderer():
    renderer = CoverageRenderer(64)
    yield renderer
    renderer.close()


@pytest.fixture(scope="module")
def atlas(renderer):
    return render_octahedral_impostor(renderer, _marked_tree(), FRAMES, TILE)


def _frame_alpha(atlas, gx: int, gy: int) -> np.ndarray:
    row, col = atlas.tile_origin(gx, gy)
    return atlas.albedo[row:row + atlas.tile, col:col + atlas.tile, 3] == 255


def _unit_directions(count: int) -> np.ndarray:
    d = np.random.default_rng(0).normal(size=(count, 3))
    d[:, 2] = np.abs(d[:, 2])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_upper_directions_round_trip_through_the_mapping():
    d = _unit_directions(2000)
    assert np.abs(octahedral_decode(octahedral_encode(d)) - d).max() < 1e-12
    assert np.abs(octahedral_encode(d)).max() <= 1.0


def test_the_square_corners_are_the_axes_and_its_centre_the_zenith():
    axes = np.array([[1, 0, 0], [0, -1, 0], [-1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64)
    assert np.allclose(octahedral_encode(axes), [[1, 1], [1, -1], [-1, -1], [-1, 1], [0, 0]])
    # Views from below the horizon are taken onto it.
    assert np.allclose(octahedral_encode([[1.0, 0.0, -0.5]]), [[1.0, 1.0]])


def test_each_frame_is_blended_alone_from_its_own_direction():
    directions = frame_directions(FRAMES).reshape(-1, 3)
    cells, weights = frame_weights(directions, FRAMES)
    chosen = cells[np.arange(len(cells)), weights.argmax(axis=1)]
    gy, gx = np.divmod(np.arange(FRAMES * FRAMES), FRAMES)
    assert np.allclose(weights.max(axis=1), 1.0) and np.array_equal(chosen, np.stack([gx, gy], axis=1))


def test_the_blend_weights_rebuild_the_directions_grid_point():
    d = _unit_directions(2000)
    cells, weights = frame_weights(d, 12)
    point = 0.5 * (octahedral_encode(d) + 1.0) * 11
    assert (weights >= -1e-12).all() and np.allclose(weights.sum(axis=1), 1.0)
    assert np.allclose(np.einsum("mk,mkc->mc", weights, cells), point)
    assert (np.abs(cells - point[:, None, :]) <= 1.0 + 1e-12).all()


def test_a_direction_is_within_half_a_frame_of_its_nearest_frame():
    frames = 12
    grid = frame_directions(frames)
    step = max(np.degrees(np.arccos(np.clip((grid[:, 1:] * grid[:, :-1]).sum(-1), -1, 1))).max(),
               np.degrees(np.arccos(np.clip((grid[1:] * grid[:-1]).sum(-1), -1, 1))).max())
    d = _unit_directions(2000)
    gx, gy = np.round(0.5 * (octahedral_encode(d) + 1.0) * (frames - 1)).astype(int).T
    angle = np.degrees(np.arccos(np.clip((grid[gy, gx] * d).sum(axis=1), -1, 1)))
    assert angle.max() <= step * np.sqrt(0.5) + 1e-9


def test_views_between_frames_blend_two_horizon_frames_half_and_half():
    azimuths = between_frame_azimuths(12)
    assert len(azimuths) == 4 * 11 and list(azimuths) == sorted(azimuths)
    _, weights = frame_weights(np.stack([view_direction(a, 0.0) for a in azimuths]), 12)
    assert np.allclose(np.sort(weights, axis=1), [0.0, 0.5, 0.5])


def test_frame_axes_are_right_handed_and_image_up_is_world_up_at_the_horizon():
    d = _unit_directions(200)
    right, up = frame_axes(d)
    assert np.allclose(np.cross(right, up), d) and np.allclose(right[:, 2], 0.0)
    assert np.allclose(frame_axes(np.array([0.0, -1.0, 0.0]))[1], [0.0, 0.0, 1.0])


def test_the_atlas_holds_every_frame_in_its_tile(atlas):
    side = FRAMES * TILE
    assert atlas.albedo.shape == (side, side, 4) and atlas.normal.shape == (side // 2, side // 2, 3)
    assert set(np.unique(atlas.albedo[..., 3])) == {0, 255}
    assert all(_frame_alpha(atlas, gx, gy).any() for gx in range(FRAMES) for gy in range(FRAMES))
    farthest = np.array([-0.25, 0.25, 0.0]) - [0.825, 0.0, 2.0]  # a foot of the post
    assert np.isclose(atlas.radius, 1.02 * np.linalg.norm(farthest), rtol=1e-3)
    assert np.isclose(atlas.half_width, 1.02 * np.hypot(1.9 - 0.825, 0.4), rtol=1e-3)  # the block's outer edge
    assert np.isclose(atlas.half_height, 1.02 * 2.0, rtol=1e-3)


def test_a_tile_spans_the_bounding_cylinder_as_its_frame_sees_it():
    extents = frame_extents(np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]]), 1.0, 3.0)
    assert np.allclose(extents, [[1.0, 3.0], [1.0, 1.0], [1.0, 0.8 + 3.0 * 0.6]])


def _tile_position(atlas, gx: int, gy: int, point) -> np.ndarray:
    """(column, row) where a world point (metres) lies in frame (gx, gy)'s tile, in texels (continuous)."""
    direction = frame_directions(atlas.frames)[gy, gx]
    right, up = frame_axes(direction)
    relative = np.asarray(point, np.float64) - atlas.centre
    scale = atlas.tile / (2 * frame_extents(direction, atlas.half_width, atlas.half_height))
    return np.array([relative @ right * scale[0], -(relative @ up) * scale[1]]) + atlas.tile / 2


@pytest.mark.parametrize("frame, side", [((FRAMES - 1, 0), 1),  # from -Y: +X to the image right
                                         ((0, FRAMES - 1), -1),  # from +Y: +X to the image left
                                         ((FRAMES - 1, FRAMES - 1), 0)])  # from +X: the block before the post
def test_a_horizon_frame_sees_the_block_from_its_side(atlas, frame, side):
    alpha = _frame_alpha(atlas, *frame)
    post_column = _tile_position(atlas, *frame, [0.0, 0.0, 1.0])[0]
    block = _tile_position(atlas, *frame, [1.5, 0.0, 2.5])
    assert np.sign(np.round(block[0] - post_column)) == side
    # The block's texels: in its rows, beside the post's columns (those covered 1 m up, where only the post is).
    rows = np.zeros(atlas.tile, bool)
    top, bottom = (int(_tile_position(atlas, *frame, [0, 0, z])[1]) for z in (2.9, 2.1))
    rows[top + 1:bottom] = True
    post_columns = alpha[int(_tile_position(atlas, *frame, [0, 0, 1.0])[1])]
    found_rows, found_columns = np.nonzero(alpha & rows[:, None] & ~post_columns[None, :])
    assert len(found_rows) >= 4  # from +X, only the block's edges beside the post
    assert abs(found_columns.mean() + 0.5 - block[0]) < 1.5 and abs(found_rows.mean() + 0.5 - block[1]) < 1.5


def test_the_frame_looking_down_sees_the_block_toward_plus_x(atlas):
    alpha = _frame_alpha(atlas, FRAMES // 2, FRAMES // 2)
    rows, cols = np.nonzero(alpha)
    texel = 2 * atlas.half_width / atlas.tile  # looking down, the tile spans the cylinder's width both ways
    x = (cols + 0.5 - atlas.tile / 2) * texel + atlas.centre[0]
    y = (atlas.tile / 2 - rows - 0.5) * texel + atlas.centre[1]
    assert x.max() == pytest.approx(1.9, abs=0.25) and x.min() == pytest.approx(-0.25, abs=0.25)
    assert np.abs(y).max() < 0.6  # the block's and the post's few decimetres across


def test_the_same_tree_gives_the_same_atlas_bytes(renderer, atlas):
    again = render_octahedral_impostor(renderer, _marked_tree(), FRAMES, TILE)
    assert again.albedo.tobytes() == atlas.albedo.tobytes() and again.normal.tobytes() == atlas.normal.tobytes()
    assert json.dumps(again.layout()) == json.dumps(atlas.layout())


@pytest.mark.parametrize("frames, tile, allowed", [(3, 32, "4..32"), (33, 16, "4..32"), (12, 86, "8..85"),
                                                   (16, 65, "8..64")])
def test_frames_and_atlas_sizes_out_of_range_are_refused(renderer, frames, tile, allowed):
    with pytest.raises(ImpostorError, match=allowed):
        render_octahedral_impostor(renderer, _marked_tree(), frames, tile)
    assert MAX_ATLAS_PX == 1024


def test_the_quad_faces_the_front_view_with_its_frame(atlas):
    quad = atlas.mesh()
    assert quad.n_faces == 2 and quad.n_vertices == 4
    assert np.allclose(quad.vertices[:, 1], atlas.centre[1])  # facing the view from -Y, spanning its tile
    assert np.allclose(np.abs(quad.vertices[:, 0] - atlas.centre[0]), atlas.half_width, rtol=1e-5)
    assert np.allclose(np.abs(quad.vertices[:, 2] - atlas.centre[2]), atlas.half_height, rtol=1e-5)
    gx, gy = atlas.static_frame
    assert (gx, gy) == (FRAMES - 1, 0)
    assert np.allclose(np.sort(np.unique(quad.uvs[:, 0])), [gx / FRAMES, (gx + 1) / FRAMES])
    assert np.allclose(np.sort(np.unique(quad.uvs[:, 1])), [1 - (gy + 1) / FRAMES, 1 - gy / FRAMES])


def test_the_layout_is_json_and_names_the_atlas(atlas):
    layout = json.loads(json.dumps(atlas.layout()))
    assert layout["kind"] == "octahedral" and layout["mapping"] == "hemi-octahedral"
    assert (layout["frames"], layout["tile_px"], layout["atlas_px"]) == (FRAMES, TILE, FRAMES * TILE)
    assert np.allclose(layout["centre_m"], atlas.centre) and layout["radius_m"] == atlas.radius


@pytest.fixture(scope="module")
def fine_atlas(renderer):
    return render_octahedral_impostor(renderer, _marked_tree(), 12, 64)


@pytest.mark.parametrize("azimuth", [0.0, 90.0, 33.75, between_frame_azimuths(12)[3]])
def test_from_a_frame_or_between_frames_the_silhouette_is_the_trees(renderer, fine_atlas, azimuth):
    tree = _marked_tree()
    camera = switch_camera(tree.bark.vertices, azimuth, 64)
    reference = closed_silhouette(renderer.coverage(tree, camera))
    shown = closed_silhouette(fine_atlas.coverage(camera))
    assert silhouette_iou(reference, shown) > 0.8
