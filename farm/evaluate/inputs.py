"""Real inputs nobody generated (`farm evaluate --inputs DIR`), scored without a ground-truth tree.

Layout (docs/evaluation.md): DIR holds point clouds (`*.xyz`, `*.txt`, `*.csv`, `*.pts`, `*.ply`, `*.las`,
`*.laz`) and sketches (image files, `farm.dataset.IMAGE_SUFFIXES`: dark strokes on light or transparent paper),
each sketch optionally with a reference dictionary beside it (`NAME.json`, the tree the sketch was drawn from).
Subfolders are not read.

- A cloud goes through the cloud method (`reconstruct.from_cloud`): the share of its points within 10 cm of the
  reconstruction's bark and their median distance (AdTree's fit), the bark's height against the cloud's
  (`bark_height_rel_error`) and the share of its points the skeleton graph joined to the tree (connectedness).
- A sketch goes through the params method (TreeSketchNet, fitted to the drawing within `EvalSettings.fit_evals`
  candidate trees): with a reference, species and levels right or wrong and the parameter score (Weber-Penn
  references); without one, `silhouette_iou_input`: the result redrawn in the sketch's view (tsn4 front) against
  the drawing, as filled outlines (`reconstruct.fitting`: each cut to its box, scaled to one height, pen gaps closed
  and enclosed paper filled, so a contour drawing is the shape it encloses), the one measure the fit maximises.
  Its panel shows the outlines of the first guess and of the result over the drawing's.
"""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from farm.dataset import IMAGE_SUFFIXES, read_image
from species.errors import user_path

from .methods import MethodContext, MethodResult, fit_cells, joined_share
from .units import EvaluationError, Unit

# reconstruct is imported where used: the package imports torch, and reconstruct.fitting scipy, which planning an
# evaluation does not need (the command's start-up time).
if TYPE_CHECKING:
    from reconstruct.fitting import FitRecord

__all__ = ["input_units", "run_input", "SKETCH_SUFFIXES", "drawing_fit"]

SKETCH_SUFFIXES = IMAGE_SUFFIXES


def input_units(folder: str, methods: Sequence[str]):
    """(units, skipped lines) for the files in `folder`; EvaluationError for a folder without inputs."""
    from reconstruct.clouds import CLOUD_SUFFIXES

    root = Path(folder)
    if not root.is_dir():
        raise EvaluationError(f"--inputs {folder} is not a folder: allowed a folder of clouds and sketches")
    files = sorted(p for p in root.iterdir() if p.is_file())
    clouds = [p for p in files if p.suffix.lower() in CLOUD_SUFFIXES and not
              (p.suffix.lower() == ".json")]
    sketches = [p for p in files if p.suffix.lower() in SKETCH_SUFFIXES]
    if not clouds and not sketches:
        raise EvaluationError(f"--inputs {folder} holds no clouds ({', '.join(CLOUD_SUFFIXES)}) "
                              f"or sketches ({', '.join(SKETCH_SUFFIXES)})")
    units, skipped = [], []
    for kind, method, found in (("clouds", "cloud", clouds), ("sketches", "params", sketches)):
        if not found:
            continue
        if method not in methods:
            skipped.append(f"{method}: {len(found)} {kind} in {folder} skipped: --methods has no {method}")
            continue
        units += [Unit(method, "input", str(root), "input", str(p)) for p in found]
    return units, skipped


def drawing_fit(result, image: np.ndarray, renderer) -> FitRecord:
    """How a params result matches its drawing: a `reconstruct.fitting.FitRecord` whose `outline` and `score` are
    the result's tree redrawn in the drawing's view (tsn4 front) as the fit draws its candidates (FIT_SIZE pixels,
    `front_outline`) against the drawing's filled outline (`outline_iou`), and whose first guess, trace and
    species are the fit's (`result.maps["fit"]`), or the result's own when it was not fitted. One measure at every
    budget: budget 0 scores what a fit's first guess scores, and a fit's result what the fit reported."""
    from reconstruct.fitting import (FIT_SIZE, FitRecord, FitTrace, drawing_outline, front_outline, outline_iou,
                                     renderer_at)

    target = drawing_outline(image)
    with renderer_at(renderer, FIT_SIZE) as drawing:
        shape = front_outline(drawing, result.skeleton, result.mesh)
    score = outline_iou(shape, target)
    fit = result.maps.get("fit")
    if fit is None:
        return FitRecord(target, shape, score, shape, score, FitTrace())
    return dataclasses.replace(fit, target=target, outline=shape, score=score)


def _run_cloud(path: Path, ctx: MethodContext) -> tuple[MethodResult, None]:
    import reconstruct
    from reconstruct import metrics
    from reconstruct.report import cloud_drawing, skeleton_drawing
    from reconstruct.scoring import depth_picture

    result = reconstruct.from_cloud(path, seed=ctx.settings.seed)
    start = time.perf_counter()
    points = result.scan.base_points  # the skeleton's frame
    fit = metrics.cloud_fit(result.skeleton, points)
    cloud_height = float(np.ptp(points[:, 2]))
    row = {"cloud_fit_10cm": fit["within"], "cloud_fit_median_m": fit["median_m"],
           "bark_height_rel_error": abs(float(result.skeleton.height) - cloud_height) / max(cloud_height, 1e-9),
           "joined_share": joined_share(result)}
    camera = ctx.renderer.cameras(result.mesh, "tsn4", np.random.default_rng(0))[0]
    cells = [("input cloud", cloud_drawing(points, 0)), ("skeleton", skeleton_drawing(result.skeleton, 0)),
             ("reconstruction", depth_picture(ctx.renderer, result.mesh, result.skeleton, camera))]
    return MethodResult(row, {**result.timings, "scoring": time.perf_counter() - start}, cells), None


def _run_sketch(path: Path, ctx: MethodContext) -> tuple[MethodResult, str | None]:
    import reconstruct
    from reconstruct import metrics
    from reconstruct.scoring import depth_picture

    net = ctx.net("sketchnet")
    image = read_image(str(path))
    result = reconstruct.from_params(image, net=net, fit_evals=ctx.settings.fit_evals, renderer=ctx.renderer)
    start = time.perf_counter()
    camera = ctx.renderer.cameras(result.mesh, "tsn4", np.random.default_rng(0))[0]
    reference_path = path.with_suffix(".json")
    row: dict[str, float] = {}
    species = None
    record = drawing_fit(result, image, ctx.renderer)
    if reference_path.exists():
        with user_path(reference_path, "read"):
            reference = json.loads(reference_path.read_text())
        species = reference.get("species")
        if species is not None:
            row["species_correct"] = float(result.params.get("species") == species)
        if "levels" in reference:
            row["levels_correct"] = float(int(result.params.get("levels", -1)) == int(reference["levels"]))
        if reference.get("generator", "weber_penn") == "weber_penn" and "levels" in reference:
            row["param_score"] = metrics.parameter_scores(net.codec, result.params, reference)["score_overall"]
    else:  # a sketch of a known tree is scored against the tree; the outline is what a drawing alone gives
        row["silhouette_iou_input"] = record.score
    cells = [("input", image), *fit_cells(record),
             ("reconstruction", depth_picture(ctx.renderer, result.mesh, result.skeleton, camera))]
    return (MethodResult(row, {**result.timings, "scoring": time.perf_counter() - start}, cells,
                         {"sketchnet": net.source}), species)


def run_input(unit, ctx: MethodContext) -> tuple[MethodResult, str | None]:
    """Reconstruct and score one real input; returns (result, the reference's species or None)."""
    path = Path(unit.tree_id)
    return _run_cloud(path, ctx) if unit.method == "cloud" else _run_sketch(path, ctx)
