"""Fitting a reconstruction to its drawing (analysis by synthesis): redraw candidate trees in the drawing's view,
compare outlines, and search for the candidate that matches best within a budget of candidate evaluations.

The parts every sketch method shares:
- `outline(mask)`: a drawing's ink or a render's coverage as a filled outline: cut to its bounding box, scaled
  to OUTLINE_HEIGHT pixels tall (a drawing has no scale), pen gaps closed and the paper enclosed by the strokes and
  the ground filled, so a contour drawing (a cloud on a stick) and a rendered crown of leaves become the same kind
  of shape.
- `outline_iou(a, b)`: two outlines on one canvas, centred on one vertical axis (a tree's), intersection over union.
- `drawing_outline(image)`: the outline of a drawing as `trainers.preprocess` finds its ink (paper, pen and scan
  levels evened out, dust removed).
- `search(score, x0, evals, rng)`: CMA-ES (the `cma` package) over a box [0, 1]^n, maximising `score`, starting
  at x0 (the method's first guess), which is always evaluated first: the result is never worse than the guess.
  The budget is a number of evaluations, not seconds, so a seed and a budget give the same result on any machine.

`fit_params` is the params method's search (the Weber-Penn dictionary around TreeSketchNet's guess).
"""
from __future__ import annotations

import contextlib
import importlib
import sys
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import cv2
import numpy as np
from scipy import ndimage

from renderers import ViewRenderer
from renderers.camera import parse_rig, perspective_camera
from renderers.silhouette_metric import silhouette_iou
from species.errors import TreefarmError

from .fit_budget import FitError

__all__ = ["OUTLINE_HEIGHT", "FitTrace", "outline", "outline_iou", "drawing_outline", "search", "front_outline",
           "renderer_at", "FitRecord", "ParamsFit", "fit_params", "PARAMS_FIT_SLOTS", "trunk_width", "TRUNK_WIDER"]

OUTLINE_HEIGHT = 128  # outlines are compared this many pixels tall
OUTLINE_CLOSING = 5   # pen gaps up to about twice this (pixels at OUTLINE_HEIGHT) are closed before filling
FOOT_BAND = 0.15      # the lowest share of an outline's height where a row is filled between its outermost strokes
SKETCH_RIG = "tsn4"   # TreeSketchNet's rig: params drawings are drawn in its first view
FIT_SIZE = 224        # params candidates are drawn this many pixels square: TreeSketchNet's input, the size its
                      # drawings' line widths are made for


# ------------------------------------------------------------------------------------------------ outlines
def outline(mask: np.ndarray) -> np.ndarray:
    """(OUTLINE_HEIGHT, W) bool filled outline of a (H, W) mask (module docstring); (0, 0) for an empty mask."""
    mask = np.asarray(mask, bool)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    if rows.size == 0:
        return np.zeros((0, 0), bool)
    box = mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1].astype(np.uint8) * 255
    width = max(1, int(round(box.shape[1] * OUTLINE_HEIGHT / box.shape[0])))
    # Area averaging keeps a thin pen line when a large drawing shrinks; any ink in a cell counts.
    scaled = cv2.resize(box, (width, OUTLINE_HEIGHT), interpolation=cv2.INTER_AREA) > 0
    # A tree stands on the ground: across the foot band, everything between the outermost strokes of a row is
    # tree, which closes a trunk drawn as two lines left open at the foot (or ending at different heights).
    foot = scaled[-max(1, int(round(FOOT_BAND * OUTLINE_HEIGHT))):]
    left = np.argmax(foot, axis=1)
    right = foot.shape[1] - 1 - np.argmax(foot[:, ::-1], axis=1)
    columns = np.arange(foot.shape[1])
    foot |= (columns >= left[:, None]) & (columns <= right[:, None]) & foot.any(axis=1)[:, None]
    # Grown by the closing radius, filled, shrunk back: a gap in a contour up to twice the radius is sealed (a
    # closing alone reopens the gap between two line ends) and the paper it encloses is filled.
    pad = OUTLINE_CLOSING + 1
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * OUTLINE_CLOSING + 1,) * 2)
    grown = cv2.dilate(np.pad(scaled, pad).astype(np.uint8), kernel)
    filled = ndimage.binary_fill_holes(grown).astype(np.uint8)
    return cv2.erode(filled, kernel)[pad:-pad, pad:-pad] > 0


def outline_iou(a: np.ndarray, b: np.ndarray) -> float:
    """IoU of two outlines (`outline`) placed on one canvas, each centred on its vertical axis; 0 if one is empty."""
    if a.size == 0 or b.size == 0:
        return 0.0
    return silhouette_iou(*_centred(a, b))


def _centred(*masks: np.ndarray) -> list[np.ndarray]:
    """Outlines of one height padded to one width, each centred on the same vertical axis."""
    width = max(m.shape[1] for m in masks)
    return [np.pad(m, ((0, 0), ((width - m.shape[1]) // 2, width - m.shape[1] - (width - m.shape[1]) // 2)))
            for m in masks]


def drawing_outline(image: np.ndarray, kind: str = "sketch") -> np.ndarray:
    """The filled outline of a drawing's ink (`trainers.preprocess.ink_mask`: dark strokes on light paper or
    light on dark, colour strokes with kind "strokes"); PreprocessError for a blank image."""
    from trainers.preprocess import ink_mask  # here, not at the top: the trainers package loads slowly

    return outline(ink_mask(image, kind))


def front_outline(renderer, skeleton, mesh) -> np.ndarray:
    """The filled outline of a tree redrawn as TreeSketchNet's drawings are drawn (`sketch_tsn` in the `tsn4`
    front view, framed as the dataset frames it, at the renderer's size), read as a drawing (`drawing_outline`):
    how the params fit sees each candidate, so a tree given its own drawing scores 1. Empty for a tree with no
    triangles or a drawing with no ink."""
    from trainers.preprocess import PreprocessError  # here, not at the top: the trainers package loads slowly

    if mesh.n_faces == 0:
        return np.zeros((0, 0), bool)
    # The rig's first view alone, framed as `ViewRenderer.cameras` frames it (the other three cost as much).
    name, azimuth, elevation = parse_rig(SKETCH_RIG).views[0]
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    camera = perspective_camera(points, azimuth, elevation, renderer.size, name=name)
    view = renderer.render_cameras(mesh, skeleton, [camera], ["sketch_tsn"], np.random.default_rng(0))[0]
    try:
        return drawing_outline(view.images["sketch_tsn"])
    except PreprocessError:
        return np.zeros((0, 0), bool)


@contextlib.contextmanager
def renderer_at(renderer, size: int):
    """`renderer` (a `renderers.ViewRenderer`) drawing `size` px squares for the block, its own size given back
    after; with None, one made here and closed after."""
    own = renderer is None
    renderer = ViewRenderer(size) if own else renderer
    previous, renderer.size = renderer.size, size
    try:
        yield renderer
    finally:
        renderer.size = previous
        if own:
            renderer.close()


# ------------------------------------------------------------------------------------------------ the search
@dataclass
class FitTrace:
    """A search's record: every evaluation's score in order, and the best so far after each (what the report
    and `--verbose` show against the budget)."""

    scores: list[float] = field(default_factory=list)

    @property
    def best(self) -> list[float]:
        return np.maximum.accumulate(self.scores).tolist() if self.scores else []

    @property
    def evals(self) -> int:
        return len(self.scores)

    def add(self, score: float) -> float:
        self.scores.append(float(score))
        return float(score)


def _cma():
    """The `cma` package, imported without its optional plotting and surrogate-model extras (matplotlib.pyplot,
    scipy.stats: most of a second of a drawing's time budget, and neither is used here); each import it tries
    fails as on a machine without them, and either loads normally later."""
    if "cma" in sys.modules:
        return sys.modules["cma"]
    blocked = [name for name in ("matplotlib.pyplot", "scipy.stats") if name not in sys.modules]
    for name in blocked:
        sys.modules[name] = None  # an import of a module set to None raises ImportError
    try:
        with warnings.catch_warnings():  # its notes on the extras it found missing
            warnings.simplefilter("ignore")
            return importlib.import_module("cma")
    finally:
        for name in blocked:
            sys.modules.pop(name, None)


def search(score: Callable[[np.ndarray], float], x0: np.ndarray, evals: int, rng: np.random.Generator,
           x0_score: float | None = None, sigma: float = 0.15, popsize: int = 6,
           stop: Callable[[], bool] | None = None) -> tuple[np.ndarray, float]:
    """(best x, its score) after at most `evals` calls of `score` (higher is better) on [0, 1]^n, starting at x0
    (scored first, unless its score is given as `x0_score`), so the answer is never worse than x0; `stop()`, when
    given, is asked before each later call and ends the search when true. CMA-ES draws its samples from `rng`
    only: the same rng state gives the same calls."""
    cma = _cma()

    x0 = np.clip(np.asarray(x0, np.float64), 0.0, 1.0)
    left = evals
    if x0_score is None:
        if left <= 0:
            raise FitError("a search needs at least one evaluation to score its start")
        x0_score, left = float(score(x0)), left - 1
    best_x, best = x0, float(x0_score)
    if left <= 0 or x0.size == 0:
        return best_x, best
    options = {"bounds": [0.0, 1.0], "popsize": popsize, "verbose": -9, "seed": np.nan,
               "randn": lambda *shape: rng.standard_normal(shape), "CMA_diagonal": True,
               "tolx": 0.0, "tolfun": 0.0, "tolfunhist": 0.0, "tolflatfitness": 10**6, "tolstagnation": 10**6}
    es = cma.CMAEvolutionStrategy(x0.tolist(), sigma, options)
    while left > 0:
        candidates = es.ask()
        scores = []
        for x in candidates[:left]:
            if stop is not None and stop():
                break
            scores.append(float(score(np.asarray(x, np.float64))))
            if scores[-1] > best:
                best_x, best = np.asarray(x, np.float64), scores[-1]
        left -= len(scores)
        if len(scores) < len(candidates):
            break
        es.tell(candidates, [-v for v in scores])
    return best_x, best


# ------------------------------------------------------------------------------------------------ params
# The Weber-Penn outputs the params fit moves (regression head, key, level or None): those that shape the outline
# seen from the front (crown base, branch lengths and angles, trunk splits, leaf size). The rest keep the guess.
PARAMS_FIT_SLOTS: tuple[tuple[str, int | None], ...] = (
    ("baseSize", None), ("length", 1), ("length", 2), ("downAngle", 1), ("downAngle", 2), ("curve", 0),
    ("curve", 1), ("attractUp", 1), ("segSplits", 0), ("splitAngle", 0), ("leafScale", None), ("branches", 1),
)
SPECIES_TRIED = 3   # the network's most likely species, each grown from its guess and from its preset
# Species are tried in the network's order until those tried hold this much of its probability: a species the
# network is sure of is kept (a drawing of our own renders), an unsure read is settled by the outline.
SPECIES_SURE = 0.9
SEEDS_TRIED = 3     # decode seeds (Weber-Penn's split decisions) tried on the best species
TRUNK_ROWS = (0.86, 0.94)  # an outline's trunk: these rows (share of its height from the top), above a flared foot
TRUNK_WIDER = 1.15         # a drawn trunk this much wider than the best candidate's is tried at its width
MAX_TRUNK_RATIO = 0.15     # the trunk step's largest trunk radius over the tree's scale (Weber-Penn's `ratio`)
# The params fit also stops once its candidates have this many faces together per evaluation of its budget
# (growing and drawing a candidate takes time in proportion to its faces): a big crown's candidates cost many times
# a small one's, and the time target is per drawing.
FIT_FACES_PER_EVAL = 150_000


@dataclass
class FitRecord:
    """What a fit did, for the report and the command line: the drawing's outline, the first guess's and the
    fitted tree's outlines and scores, every evaluation's score (`trace`) and, for params, the species tried
    (name -> (outline score of its guess, the network's probability))."""

    target: np.ndarray
    first_outline: np.ndarray
    first_score: float
    outline: np.ndarray
    score: float
    trace: FitTrace
    species_scores: dict[str, tuple[float, float]] = field(default_factory=dict)

    def overlay(self, fitted: bool = True) -> np.ndarray:
        """(OUTLINE_HEIGHT, W, 3) uint8: the drawing's outline in green, the first guess's (or the fitted tree's)
        in red, where both agree yellow, on black; each centred on the vertical axis as `outline_iou` places it."""
        shown = self.outline if fitted else self.first_outline
        placed = _centred(*(m if m.size else np.zeros((OUTLINE_HEIGHT, 1), bool) for m in (self.target, shown)))
        picture = np.zeros((OUTLINE_HEIGHT, placed[0].shape[1], 3), np.uint8)
        picture[..., 1] = placed[0] * 255
        picture[..., 0] = placed[1] * 255
        return picture

    def panels(self) -> list[tuple[str, np.ndarray]]:
        """(label, `overlay`) of the first guess and of the fitted tree, each labelled with its outline IoU; the
        fitted one alone for a record of no evaluations (a result scored, not fitted)."""
        if not self.trace.evals:
            return [(f"outline IoU {self.score:.2f}", self.overlay(fitted=True))]
        return [(f"first guess: outline IoU {self.first_score:.2f}", self.overlay(fitted=False)),
                (f"fitted: outline IoU {self.score:.2f}", self.overlay(fitted=True))]


@dataclass
class ParamsFit:
    """The params fit's answer: the dictionary, the record, and the dictionary's tree as the fit grew it
    (skeleton, mesh), or None when it could not be grown."""

    params: dict
    record: FitRecord
    tree: tuple | None = None


def trunk_width(shape: np.ndarray) -> float:
    """Median width (pixels, at OUTLINE_HEIGHT) of an outline's rows in TRUNK_ROWS, between the outermost filled
    pixels of each row; 0 for an empty outline."""
    if shape.size == 0:
        return 0.0
    rows = shape[int(TRUNK_ROWS[0] * shape.shape[0]):int(TRUNK_ROWS[1] * shape.shape[0])]
    filled = rows.any(axis=1)
    if not filled.any():
        return 0.0
    left = np.argmax(rows, axis=1)
    right = rows.shape[1] - np.argmax(rows[:, ::-1], axis=1)
    return float(np.median((right - left)[filled]))


def _slot_columns(codec) -> list[tuple[str, int]]:
    """(head, column) of each PARAMS_FIT_SLOTS entry in the codec's outputs."""
    from trainers.sketchnet_codec import HEAD_TABLE, SLOTS

    columns = []
    for key, level in PARAMS_FIT_SLOTS:
        head = next(h for h, (_, keys) in HEAD_TABLE.items() if key in keys)
        column = next(i for i, slot in enumerate(SLOTS[head]) if slot.key == key and slot.level == level)
        columns.append((head, column))
    return columns


def fit_params(codec, outputs: dict, target: np.ndarray, evals: int, seed: int, renderer,
               grow: Callable[[dict], tuple] | None = None) -> ParamsFit:
    """Search TreeSketchNet's output space around its guess for the dictionary whose tree's front outline matches
    `target` (`drawing_outline` of the sketch): the guess first, then the species' own preset, then the presets of
    the network's next species (while it is unsure: SPECIES_SURE), then decode seeds
    seed + 1, ..., then the trunk at the drawn width where the drawing's is wider (`trunk_width`, TRUNK_WIDER:
    the one value allowed past the codec's training range, to MAX_TRUNK_RATIO), then CMA-ES over
    PARAMS_FIT_SLOTS (each within the codec's training range), all within `evals` (>= 1) evaluations. `grow(params) -> (skeleton, mesh)` (default `species.rebuild`)."""
    import species

    grow = grow or species.rebuild
    trace = FitTrace()
    outlines: dict[int, np.ndarray] = {}  # evaluation index -> outline, kept for the first and the best
    grown = {"faces": 0, "best": None}    # faces of every candidate so far; the best candidate's tree

    def evaluate(candidate: dict) -> float:
        tree = None
        try:
            tree = grow(candidate)
        except TreefarmError:
            shape = np.zeros((0, 0), bool)
        else:
            shape = front_outline(renderer, *tree)
            grown["faces"] += tree[1].n_faces
        value = outline_iou(shape, target)
        if not trace.scores or value > max(trace.scores):
            outlines[trace.evals], grown["best"] = shape, tree
        return trace.add(value)

    def spent() -> bool:
        """The budget is spent: `evals` candidates, or FIT_FACES_PER_EVAL faces an evaluation grown and drawn
        (counts, so the same drawing and budget stop at the same candidate on any machine); the guess is always
        scored."""
        return trace.evals >= evals or (trace.evals > 0 and grown["faces"] >= FIT_FACES_PER_EVAL * evals)

    trunk_factor = 1.0  # the trunk step's factor on every later candidate's trunk radius (`ratio`)

    def decoded(outs: dict, decode_seed: int) -> dict:
        params = codec.decode_arrays(outs, seed=int(decode_seed))[0]
        if trunk_factor != 1.0:
            params["ratio"] = min(float(params["ratio"]) * trunk_factor, MAX_TRUNK_RATIO)
        return params

    ranking = codec.species_ranking(outputs)
    probabilities = dict(ranking)
    held = np.cumsum([probability for _, probability in ranking])
    ranking = ranking[:min(SPECIES_TRIED, int(np.searchsorted(held, SPECIES_SURE)) + 1)]
    best_outputs, best_seed, best_params, best = outputs, int(seed), None, -1.0
    species_scores: dict[str, tuple[float, float]] = {}
    for rank, (name, probability) in enumerate(ranking):
        # The network's guess, then each species' own preset: a drawing far from what training drew is often
        # nearer a preset than the guess. (The guess read as another species is nearly the same tree: the
        # species only sets a few fixed values.)
        starts = [outputs] if rank == 0 else []
        starts.append(codec.as_outputs(codec.encode_arrays([species.sample(name, np.random.default_rng(seed))],
                                                           np.float64)))
        for outs in starts:
            if spent():
                break
            params = decoded(outs, seed)
            value = evaluate(params)
            species_scores[name] = (max(value, species_scores.get(name, (0.0, 0.0))[0]), probability)
            if value > best:
                best, best_outputs, best_params = value, outs, params
    first = trace.scores[0]
    species_scores.setdefault(best_params["species"], (best, probabilities.get(best_params["species"], 0.0)))
    for offset in range(1, SEEDS_TRIED):
        if spent():
            break
        params = decoded(best_outputs, seed + offset)
        value = evaluate(params)
        if value > best:
            best, best_seed, best_params = value, seed + offset, params
    # The trunk as drawn: people draw trunks wider than trees grow them (and than training drew them); one
    # evaluation tries the guess's trunk radius scaled to the drawn trunk's width, kept for the search if better.
    if not spent():
        factor = trunk_width(target) / max(trunk_width(outlines[int(np.argmax(trace.scores))]), 1e-9)
        if factor > TRUNK_WIDER:
            trunk_factor = factor
            params = decoded(best_outputs, best_seed)
            value = evaluate(params)
            if value > best:
                best, best_params = value, params
            else:
                trunk_factor = 1.0
    left = evals - trace.evals
    if not spent():
        columns = _slot_columns(codec)
        ranges = {head: codec.normalised_range(head) for head, _ in columns}
        low = np.array([ranges[h][0][c] for h, c in columns])
        high = np.array([ranges[h][1][c] for h, c in columns])
        span = np.where(high > low, high - low, 1.0)
        guess = np.array([float(np.asarray(best_outputs[h])[0, c]) for h, c in columns])
        x0 = np.clip((guess - low) / span, 0.0, 1.0)
        chosen: dict[bytes, dict] = {}

        def moved(x: np.ndarray) -> dict:
            outs = {k: np.array(v, copy=True) for k, v in best_outputs.items()}
            for (head, column), value in zip(columns, low + x * span):
                outs[head][0, column] = value
            return outs

        def score(x: np.ndarray) -> float:
            params = decoded(moved(x), best_seed)
            value = evaluate(params)
            chosen[x.tobytes()] = params
            return value

        x, value = search(score, x0, left, np.random.default_rng(best_seed), x0_score=best, stop=spent)
        if value > best:
            best, best_params = value, chosen[x.tobytes()]
    best_index = int(np.argmax(trace.scores))
    return ParamsFit(best_params, FitRecord(target, outlines[0], first, outlines[best_index], best, trace,
                                            species_scores), grown["best"])
