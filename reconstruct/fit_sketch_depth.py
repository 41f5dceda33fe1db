"""The sketch-depth method's fit to its drawing: the traced main branches stay where they were drawn, and the crown
envelope and the growth settings move until the tree grown from them fills the drawn outline and no more.

A candidate is a point of [0, 1]^n, one coordinate per `Knob` of SKETCH_DEPTH_KNOBS: how far the crown envelope
is widened or narrowed in the drawing (pixels), and factors on the colonization settings that decide how far
growth reaches into it and how much of it leaves cover (marker density, occupancy and perception radii, leaf
size). The network's guess is the point where every offset is 0 and every factor 1. `fit_sketch_depth` grows each
candidate with the method's own growth (a callable, so this module knows nothing of depth maps), renders its
coverage in the drawing's camera, compares filled outlines over the drawing's window (`window_outline`: where
and how large, not only the shape) and searches with `reconstruct.fitting.search`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np
from scipy import ndimage

from renderers.camera import Camera
from renderers.silhouette_metric import silhouette_iou
from species.colonization import validate
from species.colonization.params import SCHEMA
from species.errors import TreefarmError
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

from ._sketch_arrays import disc
from .fit_budget import FitError
from .fitting import FitRecord, FitTrace, outline, search

__all__ = ["Knob", "SKETCH_DEPTH_KNOBS", "SketchDepthFit", "knob_settings", "fit_sketch_depth", "GUESS_SETTINGS",
           "window_outline", "window_iou", "WINDOW_PX", "WINDOW_PAD", "settings_params", "offset_mask",
           "FIT_NODE_BUDGET", "evaluations_for"]


@dataclass(frozen=True)
class Knob:
    """One fitted setting: its name, its range and where the guess sits in it. A `factor` knob multiplies the
    preset's value on a log scale (its guess is 1); an offset knob adds to it (its guess is 0)."""

    name: str
    low: float
    high: float
    factor: bool = True

    @property
    def guess(self) -> float:
        return 1.0 if self.factor else 0.0

    def at(self, x: float) -> float:
        """The setting at coordinate x in [0, 1]."""
        if self.factor:
            return float(np.exp(np.log(self.low) + x * (np.log(self.high) - np.log(self.low))))
        return float(self.low + x * (self.high - self.low))

    def coordinate(self, value: float) -> float:
        """The coordinate of a setting (`at`'s inverse)."""
        if self.factor:
            return float((np.log(value) - np.log(self.low)) / (np.log(self.high) - np.log(self.low)))
        return float((value - self.low) / (self.high - self.low))


# The crown envelope's offset is in pixels of a 256 px drawing (the growth scales it to the maps' size); the
# factors multiply the preset's draw. The ranges keep every colonization setting within its schema.
SKETCH_DEPTH_KNOBS: tuple[Knob, ...] = (
    Knob("envelope_px", -8.0, 12.0, factor=False),
    Knob("marker_density", 0.5, 2.0),
    Knob("occupancy_radius", 0.5, 1.5),
    Knob("perception_radius", 0.7, 2.0),
    Knob("leaf_size", 0.6, 3.0),
)
# The drawing's window is compared this many pixels square, on a margin where a candidate may spill past it;
# pen gaps up to about twice WINDOW_CLOSING pixels are closed (the crown outline the evaluation compares).
WINDOW_PX = 256
WINDOW_PAD = 32
WINDOW_CLOSING = 6
GUESS_SETTINGS = {knob.name: knob.guess for knob in SKETCH_DEPTH_KNOBS}
# A candidate's cost grows with its tree (the colonization's nodes): a fit stops once its candidates would have
# grown about this many nodes together, counted from the guess's size, so a drawing of a large tree stays near the
# time target; a count, like the budget, so the same drawing and seed still give the same bytes.
FIT_NODE_BUDGET = 64_000


def knob_settings(x: np.ndarray) -> dict[str, float]:
    """{knob name: setting} at a point of [0, 1]^n."""
    return {knob.name: knob.at(float(v)) for knob, v in zip(SKETCH_DEPTH_KNOBS, np.clip(x, 0.0, 1.0))}


def settings_params(params: dict, settings: dict[str, float]) -> dict:
    """The growth dictionary with a fit's factors applied (SKETCH_DEPTH_KNOBS),
    each kept within its schema range; the perception radius stays beyond the occupancy radius."""
    grown = dict(params)
    for key in ("marker_density", "occupancy_radius", "perception_radius", "leaf_size"):
        field = SCHEMA[key]
        grown[key] = float(np.clip(params[key] * settings[key], field.low, field.high))
    grown["max_markers"] = int(min(SCHEMA["max_markers"].high, round(params["max_markers"]
                                                                      * max(1.0, settings["marker_density"]))))
    grown["perception_radius"] = max(grown["perception_radius"], 1.25 * grown["occupancy_radius"])
    return validate(grown)


def offset_mask(mask: np.ndarray, offset: int) -> np.ndarray:
    """The mask grown (offset > 0) or shrunk (offset < 0) by |offset| px; shrinking never empties it."""
    if offset > 0:
        return ndimage.binary_dilation(mask, disc(offset))
    shrunk = ndimage.binary_erosion(mask, disc(-offset))
    return shrunk if shrunk.any() else mask


@dataclass
class SketchDepthFit:
    """The fit's answer: the settings of the best tree (GUESS_SETTINGS when nothing beat the guess), that tree's
    growth dictionary, skeleton and mesh, and the record."""

    settings: dict[str, float]
    params: dict
    skeleton: Skeleton
    mesh: TreeMesh
    record: FitRecord


Grown = tuple[dict, Skeleton, TreeMesh]


def window_outline(mask: np.ndarray, size: int = WINDOW_PX, pad: int = WINDOW_PAD) -> np.ndarray:
    """(size + 2 pad) square bool: a mask over the drawing's window scaled to `size` px, pen gaps closed, enclosed
    paper filled, on a margin of `pad` px (where a candidate may spill past the window)."""
    mask = np.asarray(mask, bool).astype(np.uint8) * 255
    border = pad + WINDOW_CLOSING + 1
    # Area averaging keeps a thin pen line when a large drawing shrinks; any ink in a cell counts.
    scaled = np.pad(cv2.resize(mask, (size, size), interpolation=cv2.INTER_AREA) > 0, border)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * WINDOW_CLOSING + 1,) * 2)
    closed = cv2.morphologyEx(scaled.astype(np.uint8), cv2.MORPH_CLOSE, kernel) > 0
    cut = WINDOW_CLOSING + 1
    return ndimage.binary_fill_holes(closed)[cut:-cut, cut:-cut]


def window_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two masks of one window; 0 when both are empty."""
    return silhouette_iou(a, b) if a.any() or b.any() else 0.0


def evaluations_for(evals: int, guess_nodes: int) -> int:
    """The evaluations a fit of budget `evals` spends on a tree whose guess has `guess_nodes` nodes: the budget,
    or fewer when that many candidates of the guess's size would pass FIT_NODE_BUDGET nodes (at least 1, the
    guess itself)."""
    return max(1, min(int(evals), FIT_NODE_BUDGET // max(int(guess_nodes), 1)))


def fit_sketch_depth(grow: Callable[[dict[str, float]], Grown], first: Grown, ink: np.ndarray, evals: int,
                     rng: np.random.Generator, renderer, camera: Camera) -> SketchDepthFit:
    """Search SKETCH_DEPTH_KNOBS for the tree whose filled outline in `camera` best matches the drawing's, within
    `evals` (>= 1) evaluations (fewer for a large guess: `evaluations_for`), the first being the guess `first` =
    grow(GUESS_SETTINGS) as already grown.

    ink    : (H, W) bool, the drawing's ink over its window (the window the maps and the input camera share).
    camera : the input camera in the grown tree's frame, widened to WINDOW_PX + 2 WINDOW_PAD px with the window
             WINDOW_PX px in its middle (so both outlines lie on one pixel grid).
    grow(settings) -> (params, skeleton, mesh) grows a candidate (with the same random draws for every one, so
    they differ by their settings only); a candidate that cannot grow scores 0. `rng` draws the search's samples.
    The score is the IoU of the two filled outlines (`window_outline`): unlike `fitting.outline_iou` it keeps
    where and how large the tree is, which the traced main branches fix. The record holds the outlines cut to
    their boxes (`fitting.outline`), as the report shows every fit."""
    if evals < 1:
        raise FitError(f"a fit needs at least one evaluation; got {evals}")
    target = window_outline(ink)
    if camera.width != target.shape[1] or camera.height != target.shape[0]:
        raise FitError(f"the fit's camera is {camera.width}x{camera.height} px: allowed {target.shape[1]} px "
                       "square (WINDOW_PX + 2 WINDOW_PAD)")
    trace = FitTrace()
    best: dict = {}

    def evaluate(settings: dict[str, float], grown: Grown | None = None) -> float:
        try:
            grown = grown or grow(settings)
        except TreefarmError:
            return trace.add(0.0)
        covered = (renderer.silhouette_masks(grown[2], [camera])[0] if grown[2].n_faces
                   else np.zeros_like(target))
        shape = window_outline(covered, camera.width, 0)
        value = window_iou(shape, target)
        if not best or value > best["score"]:
            best.update(score=value, settings=settings, grown=grown, outline=shape)
        if not trace.scores:
            best["first_outline"] = shape
        return trace.add(value)

    evals = evaluations_for(evals, len(first[1]))
    first_score = evaluate(dict(GUESS_SETTINGS), first)
    x0 = np.array([knob.coordinate(knob.guess) for knob in SKETCH_DEPTH_KNOBS])
    search(lambda x: evaluate(knob_settings(x)), x0, evals - 1, rng, x0_score=first_score)
    params, skeleton, mesh = best["grown"]
    record = FitRecord(outline(target), outline(best["first_outline"]), first_score, outline(best["outline"]),
                       best["score"], trace)
    return SketchDepthFit(best["settings"], params, skeleton, mesh, record)
