"""The two-view method's fit (`reconstruct.fitting`): the growth settings of its twigs, leaves and crown outlines
searched so that the tree, redrawn in both drawings' orthographic views, fills the crown both drawings show.

In: the drawings' ink, their frames (`CrownOutline`: where the tree base sits, pixels per metre), a `grow` that
turns settings into a tree (the main skeleton stays as it was lifted from the drawings). Out: a `TwoViewFit`: the
chosen settings, the tree grown with them and a `FitRecord` (both views side by side).

The drawings show the main branches only, not the crown; the crown each drawing stands for (`drawn_crown`) is the
strokes with the gaps between branches closed, enclosed paper filled, and a sleeve around every stroke, where twigs
and leaves reach past the drawn branches. A candidate's crown is its coverage in the view with leaf-sized gaps
closed, as `reconstruct.scoring` reads a crown. Its score: the mean over the two views of the crowns' IoU, in place
(the drawing fixes where the tree stands, so nothing is re-centred).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np
from scipy import ndimage

from renderers.camera import Camera, look_at
from renderers.silhouette_metric import closed_silhouette, silhouette_iou
from species import Skeleton

from ._two_view_twigs import CrownOutline
from .fit_budget import FitError, check_fit_evals
from .fitting import OUTLINE_HEIGHT, FitRecord, FitTrace, search

__all__ = ["GrowthSettings", "TwoViewFit", "FIT_SLOTS", "CROWN_GAP", "CROWN_SLEEVE", "LEAF_GAP", "DRAW_SIZE", "drawn_crown",
           "fit_camera", "coverage", "crown_iou", "fit_growth"]

# The crown a drawing stands for, as shares of the drawn tree's height (pixels its ink spans): gaps between drawn
# branches up to about twice CROWN_GAP are closed and enclosed paper filled; the crown reaches CROWN_SLEEVE past
# every stroke. Both chosen on the trees of reconstruct/specs/two-view.yaml's job seed (not the benchmark's held-out
# trees): the pair whose crown is closest (IoU) to the true trees' crowns.
CROWN_GAP = 0.1
CROWN_SLEEVE = 0.03
# A candidate's coverage has gaps up to about twice this share of the height closed (the leaves' gaps; the crown
# that reconstruct.scoring measures closes CROWN_CLOSING_PX of a 256 px view, about this share).
LEAF_GAP = 0.025
# Candidates are drawn this many pixels on the drawing's longer side: a branch is drawn at least a pixel wide, so
# coarser pixels would widen the thin twigs' share of the crown.
DRAW_SIZE = 192


@dataclass(frozen=True)
class GrowthSettings:
    """What the fit moves: the crown outlines' margin (share of the tree height the convex hull of each view's
    ink grows by; None: outlines given by the caller, not moved), and options of `grow_twigs` and `add_leaves`."""

    outline_margin: float | None
    twig: dict
    leaf: dict


# The slots the search moves, each (group, key, low, high, integer): a value, or the centre of a (lo, hi) range
# whose width stays the start's. Outside them the start's settings are kept.
FIT_SLOTS: tuple[tuple[str, str, float, float, bool], ...] = (
    ("outline", "margin", 0.0, 0.15, False),
    ("twig", "children", 2.0, 8.0, True),
    ("twig", "sigma", 0.2, 0.85, False),
    ("twig", "theta_deg", 15.0, 75.0, False),
    ("twig", "bud_span", 0.4, 1.0, False),
    ("twig", "density_limit", 2.0, 16.0, True),
    ("leaf", "length", 0.005, 0.04, False),
)


@dataclass
class TwoViewFit:
    """The fit's answer: the settings chosen, what `grow` gave for them, and the record."""

    settings: GrowthSettings
    grown: tuple
    record: FitRecord


def drawn_crown(ink: np.ndarray) -> np.ndarray:
    """(H, W) bool: the crown a drawing of main branches stands for (module docstring); ink (H, W) bool strokes."""
    rows = np.flatnonzero(ink.any(axis=1))
    height = max(int(rows[-1] - rows[0]), 1)
    gap, sleeve = int(round(CROWN_GAP * height)), int(round(CROWN_SLEEVE * height))
    pad = gap + sleeve + 1
    padded = np.pad(ink, pad).astype(np.uint8)
    closed = cv2.morphologyEx(padded, cv2.MORPH_CLOSE, _disc(gap)) if gap else padded
    filled = ndimage.binary_fill_holes(closed).astype(np.uint8)
    grown = cv2.dilate(filled, _disc(sleeve)) if sleeve else filled
    return grown[pad:-pad, pad:-pad] > 0


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def fit_camera(outline: CrownOutline, size: int) -> Camera:
    """The orthographic camera of a view the drawing was made in (`outline`: its frame), `size` pixels on the
    image's longer side: world points land where `outline.project` puts them, scaled to that size."""
    h, w = outline.mask.shape
    scale = size / max(h, w)
    width, height = max(1, int(round(w * scale))), max(1, int(round(h * scale)))
    sx, sy = width / w, height / h
    ppm = outline.pixels_per_metre
    reach = (w + h) / ppm  # metres: no point of a tree clipped by the outlines lies farther from its base
    distance = 2.0 * reach + 1.0
    eye = np.array([0.0, -distance, 0.0]) if outline.axis == 0 else np.array([distance, 0.0, 0.0])
    K = np.array([[ppm * sx, 0.0, (outline.base[0] + 0.5) * sx - 0.5],
                  [0.0, ppm * sy, (outline.base[1] + 0.5) * sy - 0.5], [0.0, 0.0, 1.0]])
    return Camera(width, height, K, look_at(eye, np.zeros(3)), "orthographic", distance - reach - 0.5,
                  distance + reach + 0.5, width / (2 * ppm * sx), height / (2 * ppm * sy),
                  name="front" if outline.axis == 0 else "side")


def coverage(skeleton: Skeleton, camera: Camera) -> np.ndarray:
    """(H, W) bool pixels of the camera's image a tree covers: every branch segment drawn as wide as its tube
    (at least a pixel), every leaf card's edges (a card is a pixel or two across at the fit's size). The mesh's
    silhouette, without building the mesh (tests/reconstruct/test_fit_two_view.py compares the two)."""
    image = np.zeros((camera.height, camera.width), np.uint8)
    child = np.flatnonzero(skeleton.parent >= 0)
    pixels = camera.project(skeleton.positions)[0]
    shift = 4
    segments = np.round(np.stack([pixels[skeleton.parent[child]], pixels[child]], axis=1) * (1 << shift))
    segments = segments.astype(np.int32)
    width = np.maximum(np.round(2.0 * skeleton.radius[child] * camera.K[0, 0]), 1).astype(np.int64)
    for value in np.unique(width):
        cv2.polylines(image, list(segments[width == value]), False, 1, int(value), cv2.LINE_8, shift)
    if skeleton.n_leaves:
        corners = camera.project(skeleton.leaf_corners().reshape(-1, 3))[0].reshape(-1, 4, 2)
        cv2.polylines(image, list(np.round(corners * (1 << shift)).astype(np.int32)), True, 1, 1, cv2.LINE_8, shift)
    return image > 0


def _at_size(mask: np.ndarray, camera: Camera) -> np.ndarray:
    """A drawing-sized mask at the camera's size: a pixel is in when at least half of what it covers is."""
    small = cv2.resize(mask.astype(np.float32), (camera.width, camera.height), interpolation=cv2.INTER_AREA)
    return small >= 0.5


def crown_iou(coverage: np.ndarray, target: np.ndarray, closing_px: int) -> tuple[float, np.ndarray]:
    """(IoU, crown): a candidate's coverage (H, W) bool with gaps up to about 2 closing_px closed, against a
    target crown (H, W) bool, in place."""
    crown = closed_silhouette(coverage, closing_px)
    return (silhouette_iou(crown, target) if crown.any() or target.any() else 0.0), crown


def _side_by_side(front: np.ndarray, side: np.ndarray) -> np.ndarray:
    """The two views' masks next to each other, OUTLINE_HEIGHT tall (what `FitRecord.overlay` draws)."""
    both = np.hstack([front, side]).astype(np.uint8)
    width = max(1, int(round(both.shape[1] * OUTLINE_HEIGHT / both.shape[0])))
    return cv2.resize(both, (width, OUTLINE_HEIGHT), interpolation=cv2.INTER_NEAREST) > 0


def _slot_start(settings: GrowthSettings, group: str, key: str) -> float:
    value = settings.outline_margin if group == "outline" else getattr(settings, group)[key]
    return float(np.mean(value)) if isinstance(value, (tuple, list)) else float(value)


def _moved(start: GrowthSettings, slots, values: np.ndarray) -> GrowthSettings:
    """The start's settings with each slot set to its value (a range keeps its width, clipped to its slot)."""
    margin, twig, leaf = start.outline_margin, dict(start.twig), dict(start.leaf)
    for (group, key, low, high, integer), value in zip(slots, values):
        value = float(round(value)) if integer else float(value)
        if group == "outline":
            margin = value
            continue
        options = twig if group == "twig" else leaf
        if isinstance(options[key], (tuple, list)):
            half = (options[key][1] - options[key][0]) / 2.0
            options[key] = (max(low, value - half), min(high, value + half))
        else:
            options[key] = int(value) if integer else value
    return GrowthSettings(margin, twig, leaf)


def fit_growth(grow: Callable[[GrowthSettings, np.random.Generator], tuple], start: GrowthSettings,
               inks: tuple[np.ndarray, np.ndarray], frames: tuple[CrownOutline, CrownOutline], evals: int,
               rng: np.random.Generator) -> TwoViewFit:
    """Search the growth settings around `start` (the method's first guess, scored first) for the tree whose crowns
    in both views match the drawings' (`drawn_crown` of `inks`, front and side (H, W) bool), within `evals` (>= 1)
    candidate trees.

    grow(settings, rng) -> (skeleton, ...): a tree, every candidate grown from a copy of `rng`'s state (so the
              first candidate is the unfitted tree and candidates differ by their settings only); `grown` is what
              it returned for the settings chosen.
    frames  : the views' CrownOutline (front, side): where the drawn tree stands in each image; candidates are
              drawn in them (`coverage`) DRAW_SIZE pixels on the longer side.
    rng     : the growth's Generator; the search draws from a Generator seeded from a copy of it.
    """
    evals = check_fit_evals(evals)
    if evals < 1:
        raise FitError(f"a fit of {evals} evaluations cannot score its first guess: allowed at least 1")
    cameras = [fit_camera(frame, DRAW_SIZE) for frame in frames]
    targets = [_at_size(drawn_crown(ink), camera) for ink, camera in zip(inks, cameras)]
    closing = [max(1, int(round(LEAF_GAP * np.ptp(np.flatnonzero(ink.any(axis=1))) * camera.height / ink.shape[0])))
               for ink, camera in zip(inks, cameras)]
    slots = tuple(s for s in FIT_SLOTS if s[0] != "outline" or start.outline_margin is not None)
    trace = FitTrace()
    kept: dict[str, tuple] = {}  # "first" and "best": (settings, grown, crowns)

    def evaluate(settings: GrowthSettings) -> float:
        grown = grow(settings, copy.deepcopy(rng))
        scored = [crown_iou(coverage(grown[0], camera), target, radius)
                  for camera, target, radius in zip(cameras, targets, closing)]
        value = float(np.mean([s for s, _ in scored]))
        if "best" not in kept or value > trace.best[-1]:
            kept["best"] = (settings, grown, [c for _, c in scored])
        return trace.add(value)

    first = evaluate(start)
    kept["first"] = kept["best"]
    if evals > 1 and slots:
        low = np.array([s[2] for s in slots])
        span = np.array([s[3] - s[2] for s in slots])
        x0 = np.clip((np.array([_slot_start(start, s[0], s[1]) for s in slots]) - low) / span, 0.0, 1.0)
        search_rng = np.random.default_rng(copy.deepcopy(rng).integers(2**63))
        search(lambda x: evaluate(_moved(start, slots, low + x * span)), x0, evals - 1, search_rng, x0_score=first)
    settings, grown, crowns = kept["best"]
    record = FitRecord(_side_by_side(*targets), _side_by_side(*kept["first"][2]), first, _side_by_side(*crowns),
                       max(trace.scores), trace)
    return TwoViewFit(settings, grown, record)
