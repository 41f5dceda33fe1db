"""Two orthogonal sketches to a tree (seed 001, the network-free method): 2D skeletons of both drawings, the
front skeleton lifted to 3D on the side drawing's strokes (or, as seed 001 lifts it, through the point cloud of
equal-height matching), twigs clipped by both crowns, mesh.

In: a front and a side drawing (dark strokes on white; the front looks along +Y, the side along -X, as the
renderers' "two-view" rig). Out: a `Reconstruction` (method "two-view": Skeleton in metres, Z up, base at the
origin; TreeMesh; stage timings and the intermediate maps).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from species import Skeleton, build_mesh
from species.timing import StageTimer
from trainers.preprocess import SPECK_SHARE, PreprocessError, paper_image

from ._two_view_brush import skeleton_2d_from_brush, stroke_centres
from ._two_view_lift import (LIFT_DISTANCE_PX, lift_main_skeleton, lift_on_side_strokes, match_equal_height,
                              skeleton_pixels)
from ._two_view_lines import LINE_RADIUS_PX, Skeleton2D, TwoViewError, skeleton_2d_from_lines
from ._two_view_twigs import (LEAF_DEFAULTS, TWIG_DEFAULTS, CrownOutline, add_leaves, grow_twigs,
                              resample_skeleton)
from .fit_two_view import GrowthSettings, fit_growth
from .fit_budget import DEFAULT_FIT_EVALS, check_fit_evals
from .result import Reconstruction

__all__ = ["two_view", "TwoViewError", "Skeleton2D", "CrownOutline", "skeleton_2d_from_lines",
           "skeleton_2d_from_brush", "stroke_centres", "match_equal_height", "skeleton_pixels",
           "lift_main_skeleton", "lift_on_side_strokes", "LIFTS", "grow_twigs", "add_leaves", "resample_skeleton",
           "ink_mask", "crown_outline", "is_brush_drawing", "DEFAULT_HEIGHT", "MESH_PARAMS", "TWIG_DEFAULTS", "LEAF_DEFAULTS",
           "LIFT_DISTANCE_PX", "LINE_RADIUS_PX", "OUTLINE_MARGIN", "NODE_SPACING", "BRUSH_SHARE", "INK_LEVEL"]

LIFTS = ("side-strokes", "equal-height")  # `two_view`'s lifts of the front skeleton to 3D, the default first
DEFAULT_HEIGHT = 8.0   # metres, when the caller gives none: a mid-sized garden or street tree
INK_LEVEL = 0.5        # a pixel at least half way from paper to ink (trainers.preprocess levels) is a stroke
# The crown outline of a view: the convex hull of its ink grown sideways by this share of the view's tree height,
# so twigs may reach a little past the drawn branch tips, as a crown does.
OUTLINE_MARGIN = 0.05
NODE_SPACING = 0.02    # the lifted main skeleton keeps a node about every this share of the height
# A drawing is in brush strokes when more than this share of its ink survives a 3x3 erosion (1-2 px pen lines
# do not survive it).
BRUSH_SHARE = 0.05
# The mesh's dictionary: bark and leaf colours of the colonization templates; default tube sides.
MESH_PARAMS = {"name": "two-view", "bark_color": [0.33, 0.25, 0.18], "leaf_color": [0.25, 0.45, 0.15]}
_MIN_SIDE = 8


@dataclass(frozen=True)
class _Frame:
    """Where the tree stands in one drawing: lowest and highest ink rows, and the trunk base column."""

    base_row: int
    top_row: int
    base_col: float

    @property
    def height_px(self) -> int:
        return self.base_row - self.top_row


def _checked_image(image, name: str) -> np.ndarray:
    if not isinstance(image, np.ndarray):
        raise TwoViewError(f"{name} is a {type(image).__name__}: allowed a numpy uint8 image array")
    if image.ndim not in (2, 3) or (image.ndim == 3 and image.shape[2] != 3):
        raise TwoViewError(f"{name} has shape {image.shape}: allowed (H, W) grey or (H, W, 3) colour")
    if image.dtype != np.uint8:
        raise TwoViewError(f"{name} has dtype {image.dtype}: allowed uint8 (0 = black ink, 255 = white paper)")
    if min(image.shape[:2]) < _MIN_SIDE:
        raise TwoViewError(f"{name} is {image.shape[1]} x {image.shape[0]} px: allowed at least "
                           f"{_MIN_SIDE} x {_MIN_SIDE}")
    return image


def ink_mask(image: np.ndarray, name: str = "image") -> np.ndarray:
    """(H, W) bool stroke pixels of a drawing: (H, W) or (H, W, 3) uint8, dark strokes on light paper (or light
    on dark), levelled by `trainers.preprocess.paper_image` so grey scans and tinted paper read alike.
    Raises TwoViewError for a wrong shape or dtype and for a blank image."""
    image = _checked_image(image, name)
    try:
        ink = paper_image(image, "sketch")[..., 0]
    except PreprocessError as exc:
        raise TwoViewError(f"{name}: {exc}") from exc
    mask = ink >= INK_LEVEL
    if not mask.any():
        raise TwoViewError(f"{name} is blank: no stroke is darker than half way from paper to ink")
    return mask


def is_brush_drawing(mask: np.ndarray) -> bool:
    """Whether a stroke mask (H, W) bool is drawn with a brush rather than a 1-pixel pen (see BRUSH_SHARE)."""
    core = cv2.erode(mask.astype(np.uint8), np.ones((3, 3), np.uint8))
    return bool(np.count_nonzero(core) > BRUSH_SHARE * np.count_nonzero(mask))


def _without_specks(mask: np.ndarray) -> np.ndarray:
    """The mask without ink pieces smaller than trainers.preprocess.SPECK_SHARE of the image (scan dust); the mask
    as it is if only specks are left."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    big = stats[:, cv2.CC_STAT_AREA] >= max(2.0, SPECK_SHARE * mask.size)
    big[0] = False
    kept = big[labels]
    return kept if kept.any() else mask


def crown_outline(mask: np.ndarray, margin_px: float) -> np.ndarray:
    """(H, W) bool crown outline of a view: the filled convex hull of its stroke pixels, grown by `margin_px`
    but never above the highest or below the lowest stroke row (the drawing fixes the tree's height)."""
    ys, xs = np.nonzero(mask)
    hull = cv2.convexHull(np.column_stack([xs, ys]).astype(np.int32))
    outline = np.zeros(mask.shape, np.uint8)
    cv2.fillPoly(outline, [hull.reshape(-1, 2)], 1)
    grow = int(round(margin_px))
    if grow > 0:
        outline = cv2.dilate(outline, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * grow + 1, 2 * grow + 1)))
        outline[:ys.min()] = 0
        outline[ys.max() + 1:] = 0
    return outline > 0


def _frame(mask: np.ndarray, skeleton: Skeleton2D, name: str) -> _Frame:
    rows = np.flatnonzero(mask.any(axis=1))
    frame = _Frame(int(rows[-1]), int(rows[0]), float(skeleton.points[0, 0]))
    if frame.height_px < 2:
        raise TwoViewError(f"{name}'s strokes span {frame.height_px + 1} row(s): draw the tree from its base to "
                           f"its top (at least 3 rows)")
    return frame


def _given_outline(given, mask: np.ndarray, name: str) -> np.ndarray | None:
    """A caller's crown outline checked, or None where the method draws its own (`crown_outline`)."""
    if given is None:
        return None
    given = np.asarray(given)
    if given.shape != mask.shape:
        raise TwoViewError(f"{name} outline has shape {given.shape}: allowed the image's {mask.shape}")
    given = given.astype(bool)
    if not given.any():
        raise TwoViewError(f"{name} outline is empty: allowed a mask that is True inside the crown")
    return given


def _check_height(height) -> float:
    if height is None:
        return DEFAULT_HEIGHT
    if isinstance(height, bool) or not isinstance(height, (int, float, np.integer, np.floating)) \
            or not np.isfinite(height) or not 0.0 < float(height) <= 200.0:
        raise TwoViewError(f"height {height!r} is invalid: allowed metres in (0, 200]")
    return float(height)


def two_view(front: np.ndarray, side: np.ndarray, *, height: float | None = None, rng: np.random.Generator,
             brush: bool | None = None, front_outline=None, side_outline=None, twig_options: dict | None = None,
             leaf_options: dict | None = None, fit_evals: int = DEFAULT_FIT_EVALS,
             lift: str = "side-strokes") -> Reconstruction:
    """A tree from two orthogonal drawings (seed 001, digest 2).

    front, side : (H, W) grey or (H, W, 3) colour uint8 images of one size, dark strokes on light paper: the trunk
                  and main branches seen from the front (world X to the right) and from the side (world Y to the
                  right), Z up. Their scales may differ: each view is normalised on its trunk base (lowest ink
                  row, the base column of its 2D skeleton's root) and its tree height (rows the ink spans).
    height      : metres from the base to the top of the drawn tree (default DEFAULT_HEIGHT).
    rng         : numpy Generator for the twigs and leaves (and the fit's search); the same seed and fit_evals give
                  the same bytes.
    brush       : True for brush strokes (radius from width; pieces may be apart), False for 1-pixel strokes
                  (must be connected), None to tell from the drawings (`is_brush_drawing` on either view).
    front_outline, side_outline : optional (H, W) bool crown masks in each image's pixels; default
                  `crown_outline` of the ink (convex hull + OUTLINE_MARGIN of the tree height).
    twig_options, leaf_options : overrides of TWIG_DEFAULTS and LEAF_DEFAULTS (the fit's start).
    lift        : "side-strokes" (`lift_on_side_strokes`: every branch kept on the side drawing's strokes) or
                  "equal-height" (seed 001's: `lift_main_skeleton` through `match_equal_height`'s cloud).
    fit_evals   : candidate trees the fit may grow and redraw in both views (`reconstruct.fit_two_view`: the
                  outline margin and the twig and leaf settings move, the main skeleton stays); 0 grows the first
                  guess as it is, with the options above.
    Timings: "ink", "skeleton_2d", "lift", "main_skeleton", "twigs" (fit_evals 0) or "fit" (which grows
    every candidate's twigs), "mesh". Maps: "brush" (bool, the
    stroke kind used), "metres_per_pixel" and "side_scale" (front pixels per side pixel), "front_2d" and "side_2d"
    (Skeleton2D; the side mapped into the front's pixels), "lifted" (N, 3) pixels (front column, row, side
    column), "main" (the main Skeleton, metres) and "main_skeleton" (its nodes), "twig_level" (N,)
    uint8, "outlines" (front, side) CrownOutline; with fitting, "fit" (a `reconstruct.fitting.FitRecord`, both
    views side by side) and "growth" (the `GrowthSettings` chosen).
    Radii: the pipe model with exponent 2.5 (TWIG_DEFAULTS) and tips 0.002 x height; with brush strokes the main skeleton keeps
    its drawn radii and no twig is thicker than the main branch it grows from.
    Raises TwoViewError for images that are blank, not (H, W) / (H, W, 3) uint8, of different sizes, 1-pixel
    strokes in several pieces, bad outlines, heights or options.
    """
    timer = StageTimer()
    lap, timings = timer.lap, timer.seconds

    if not isinstance(rng, np.random.Generator):
        raise TwoViewError(f"rng is a {type(rng).__name__}: allowed a numpy.random.Generator "
                           f"(numpy.random.default_rng(seed))")
    height = _check_height(height)
    fit_evals = check_fit_evals(fit_evals)
    if lift not in LIFTS:
        raise TwoViewError(f"lift {lift!r} is not known: allowed {', '.join(map(repr, LIFTS))}")
    front_ink, side_ink = ink_mask(front, "front image"), ink_mask(side, "side image")
    if front_ink.shape != side_ink.shape:
        raise TwoViewError(f"the front image is {front_ink.shape[1]} x {front_ink.shape[0]} px and the side image "
                           f"{side_ink.shape[1]} x {side_ink.shape[0]} px: draw both views on images of one size")
    if brush is None:
        brush = is_brush_drawing(front_ink) or is_brush_drawing(side_ink)
    brush = bool(brush)
    lap("ink")
    if brush:
        front_ink, side_ink = _without_specks(front_ink), _without_specks(side_ink)
        front_2d = skeleton_2d_from_brush(front_ink, "front image")
        side_2d = skeleton_2d_from_brush(side_ink, "side image")
    else:
        front_2d = skeleton_2d_from_lines(front_ink, "front image")
        side_2d = skeleton_2d_from_lines(side_ink, "side image")
    lap("skeleton_2d")
    front_frame = _frame(front_ink, front_2d, "the front image")
    side_frame = _frame(side_ink, side_2d, "the side image")
    given = (_given_outline(front_outline, front_ink, "front"), _given_outline(side_outline, side_ink, "side"))
    scale = front_frame.height_px / side_frame.height_px  # front pixels per side pixel
    side_in_front = side_2d.transformed(scale, (side_frame.base_col, side_frame.base_row),
                                        (front_frame.base_col, front_frame.base_row))
    dense = front_2d.densified(1.0)
    if lift == "side-strokes":
        lifted = lift_on_side_strokes(dense, side_in_front)
    else:
        lifted = lift_main_skeleton(dense, match_equal_height(front_2d, side_in_front))
    lap("lift")
    mpp = height / front_frame.height_px
    world = np.column_stack([lifted[:, 0] - front_frame.base_col, lifted[:, 2] - front_frame.base_col,
                             front_frame.base_row - lifted[:, 1]]) * mpp
    root = world[0].copy()
    world -= root
    order = dense.branch_order[dense.branch]
    main = resample_skeleton(world, dense.parent, order, np.maximum(dense.radius, LINE_RADIUS_PX) * mpp,
                             NODE_SPACING * height)
    ppm = 1.0 / mpp
    places = (((front_frame.base_col + root[0] * ppm, front_frame.base_row - root[2] * ppm), ppm),
              ((side_frame.base_col + root[1] * ppm / scale, side_frame.base_row - root[2] * ppm / scale),
               ppm / scale))
    lap("main_skeleton")
    inks, frames = (front_ink, side_ink), (front_frame, side_frame)

    def grow(settings: GrowthSettings, growth_rng: np.random.Generator):
        """The tree of the main skeleton with twigs and leaves grown by `settings`, and its two CrownOutlines."""
        outlines = tuple(CrownOutline(mask if mask is not None else
                                      crown_outline(ink, settings.outline_margin * frame.height_px), axis, *place)
                         for axis, (mask, ink, frame, place) in enumerate(zip(given, inks, frames, places)))
        tree, level = grow_twigs(main, *outlines, growth_rng, **settings.twig)
        if brush:
            tree = _with_drawn_radii(tree, level, main.radius)
        return add_leaves(tree, level, growth_rng, **settings.leaf), level, outlines

    settings = GrowthSettings(None if given[0] is not None and given[1] is not None else OUTLINE_MARGIN,
                              {**TWIG_DEFAULTS, **(twig_options or {})}, {**LEAF_DEFAULTS, **(leaf_options or {})})
    maps = {}
    if fit_evals:
        frames_px = tuple(CrownOutline(np.zeros(ink.shape, bool), axis, *place)
                          for axis, (ink, place) in enumerate(zip(inks, places)))
        fit = fit_growth(grow, settings, inks, frames_px, fit_evals, rng)
        (skeleton, level, outlines), maps["fit"], maps["growth"] = fit.grown, fit.record, fit.settings
        lap("fit")
    else:
        skeleton, level, outlines = grow(settings, rng)
        lap("twigs")
    mesh = build_mesh(skeleton, MESH_PARAMS)
    lap("mesh")
    maps.update({"brush": brush, "metres_per_pixel": mpp, "side_scale": scale, "front_2d": front_2d,
                 "side_2d": side_in_front, "lifted": lifted, "main": main,
                 "main_skeleton": main.positions, "twig_level": level, "outlines": outlines})
    return Reconstruction("two-view", skeleton, mesh, timings=timings, maps=maps)


def _with_drawn_radii(skeleton: Skeleton, level: np.ndarray, drawn: np.ndarray) -> Skeleton:
    """Main nodes (level 0, the first len(drawn)) take their drawn radius; a twig is capped at the drawn radius of
    the main node it grows from."""
    n_main = len(drawn)
    parent = skeleton.parent.astype(np.int64)
    anchor = np.arange(len(skeleton))
    while True:
        twig = anchor >= n_main
        if not twig.any():
            break
        anchor[twig] = parent[anchor[twig]]
    radius = np.minimum(skeleton.radius, drawn[anchor])
    radius[:n_main] = drawn
    return Skeleton(skeleton.positions, skeleton.parent, radius, skeleton.order, skeleton.leaves,
                    skeleton.leaf_node)
