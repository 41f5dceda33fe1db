"""The visual hull (issue 51): carved from exact masks of a known shape it holds the shape and lies within about
a voxel of it; a few wrong masks are outvoted; masks all empty are refused."""
from __future__ import annotations

import numpy as np
import pytest

from reconstruct.visual_hull import HullError, PinholeView, carve, free_votes

SIZE = 96
FOCAL = 110.0
RADII = np.array([1.0, 1.0, 0.7])      # an ellipsoid crown, metres
CENTRE = np.array([0.0, 0.0, 2.0])
VOXEL = 0.1


def _view(azimuth: float, elevation: float, distance: float = 6.0) -> PinholeView:
    a, e = np.radians(azimuth), np.radians(elevation)
    forward = -np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    centre = CENTRE - distance * forward
    right = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-6:
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return PinholeView(np.stack([right, down, forward]), centre, (FOCAL, FOCAL), (SIZE / 2, SIZE / 2), (SIZE, SIZE))


def _exact_mask(view: PinholeView) -> np.ndarray:
    """Pixels whose ray through the pixel centre meets the ellipsoid."""
    v, u = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    rays = np.stack([(u - view.principal[0]) / FOCAL, (v - view.principal[1]) / FOCAL, np.ones_like(u)], -1)
    rays = rays.reshape(-1, 3) @ view.rotation          # camera to world directions
    o, d = (view.centre - CENTRE) / RADII, rays / RADII   # in the unit sphere's frame
    a, b, c = (d * d).sum(1), 2 * (o * d).sum(1), (o * o).sum() - 1.0
    return (b * b - 4 * a * c >= 0).reshape(SIZE, SIZE)


@pytest.fixture(scope="module")
def views():
    return [_view(az, el) for el in (-40.0, 0.0, 40.0) for az in range(0, 360, 30)] + [_view(0.0, 89.0)]


BOUNDS = np.array([CENTRE - 1.6, CENTRE + 1.6])


def _inside_ellipsoid(points: np.ndarray, grow: float = 0.0) -> np.ndarray:
    return (((points - CENTRE) / (RADII + grow)) ** 2).sum(axis=1) <= 1.0


def test_hull_of_exact_masks_holds_the_shape_within_a_voxel(views):
    hull = carve([_exact_mask(v) for v in views], views, BOUNDS, VOXEL)
    rng = np.random.default_rng(0)
    samples = CENTRE + RADII * rng.uniform(-1, 1, (20000, 3))
    samples = samples[_inside_ellipsoid(samples)]
    assert hull.space().contains(samples).all()                           # holds the shape
    assert CENTRE[2] + RADII[2] <= hull.top() <= CENTRE[2] + RADII[2] + 2 * VOXEL
    centres = hull.centres()
    assert _inside_ellipsoid(centres, grow=VOXEL * np.sqrt(3)).all()      # within a voxel (its diagonal) of it
    volume = hull.occupancy.sum() * VOXEL ** 3
    assert volume < 1.5 * 4 / 3 * np.pi * np.prod(RADII)                  # and not a loose box round it


def test_a_wrong_mask_is_outvoted_but_not_when_all_must_agree(views):
    masks = [_exact_mask(v) for v in views]
    masks[3] = np.zeros_like(masks[3])                                    # a photo whose mask missed the tree
    rng = np.random.default_rng(1)
    samples = CENTRE + RADII * rng.uniform(-1, 1, (5000, 3))
    samples = samples[_inside_ellipsoid(samples)]
    assert carve(masks, views, BOUNDS, VOXEL, agree=0.8).space().contains(samples).all()
    with pytest.raises(HullError, match="enough photos"):                # one empty mask carves it all away
        carve(masks, views, BOUNDS, VOXEL, agree=1.0)


def test_points_restore_what_a_few_wrong_masks_carved_but_not_what_no_mask_holds(views):
    centre = CENTRE[None, :]
    masks = [_exact_mask(v) for v in views]
    rows, columns = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    for view, mask in list(zip(views, masks))[::3]:                      # a third of the masks miss the middle
        (u, v), = view.project(centre)[0]
        mask[(columns - u) ** 2 + (rows - v) ** 2 < 6.0 ** 2] = False
    outside = np.array([[0.0, 0.0, 3.3]])                                 # above the crown, inside the bounds
    assert not carve(masks, views, BOUNDS, VOXEL).space().contains(centre).any()
    restored = carve(masks, views, BOUNDS, VOXEL, points=np.concatenate([centre, outside])).space()
    assert restored.contains(centre).all()
    assert not restored.contains(outside).any()


def test_empty_masks_or_no_views_are_refused(views):
    with pytest.raises(HullError, match="empty"):
        carve([np.zeros((SIZE, SIZE), bool)] * len(views), views, BOUNDS, VOXEL)
    with pytest.raises(HullError, match="at least one registered photo"):
        carve([], [], BOUNDS, VOXEL)


def test_sightlines_free_the_voxels_they_cross_short_of_the_point_seen():
    start, end = np.array([[-5.0, 0.5, 0.5]]), np.array([[8.5, 0.5, 0.5]])   # along the first row of voxels
    votes = free_votes((10, 10, 10), np.zeros(3), 1.0, start, end)
    assert votes[:7, 0, 0].tolist() == [1] * 7 and votes.sum() == 7            # stops 1.5 voxels short of it
    twice = free_votes((10, 10, 10), np.zeros(3), 1.0, np.repeat(start, 2, 0), np.repeat(end, 2, 0))
    assert (twice == 2 * votes).all()
    above = free_votes((10, 10, 10), np.zeros(3), 1.0, start + [0, 0, 20], end + [0, 0, 20])
    assert not above.any()                                                      # outside the grid


def test_ground_seen_under_the_crown_carves_what_every_mask_keeps(views):
    # every mask also covers a skirt under the crown (a shadow taken for the tree); cameras that saw the ground
    # there through it carve it, and the crown stays
    skirt = np.array([CENTRE[0], CENTRE[1], 0.8])
    masks = []
    for view in views:
        mask = _exact_mask(view)
        (u, v), = view.project(skirt[None, :])[0]
        rows, columns = np.mgrid[0:SIZE, 0:SIZE] + 0.5
        mask[(columns - u) ** 2 + (rows - v) ** 2 < 8.0 ** 2] = True
        masks.append(mask)
    side = [v for v in views if abs(v.centre[2] - CENTRE[2]) < 1.0]           # the level cameras
    away = np.array([np.append(CENTRE[:2] - v.centre[:2], 0.0) for v in side])
    ends = np.array([0.0, 0.0, 0.5]) + 1.4 * away / np.linalg.norm(away, axis=1, keepdims=True)
    starts = np.array([v.centre for v in side])                                # each saw the ground beyond the axis
    low = np.array([0.0, 0.0, 0.5 + 1.5 * 1.4 / 7.4])                           # where they all pass over it
    assert carve(masks, views, BOUNDS, VOXEL).space().contains(low[None, :]).all()
    hull = carve(masks, views, BOUNDS, VOXEL, sightlines=(starts, ends))
    assert not hull.space().contains(low[None, :]).any()
    rng = np.random.default_rng(2)
    crown = CENTRE + RADII * rng.uniform(-1, 1, (4000, 3))
    crown = crown[_inside_ellipsoid(crown)]
    assert hull.space().contains(crown).mean() >= 0.9
