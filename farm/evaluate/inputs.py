"""Real inputs nobody generated (`farm evaluate --inputs DIR`), scored without a ground-truth tree.

Layout (docs/evaluation.md): DIR holds point clouds (`*.xyz`, `*.txt`, `*.csv`, `*.pts`, `*.ply`, `*.las`,
`*.laz`) and sketches (image files, `farm.dataset.IMAGE_SUFFIXES`: dark strokes on light or transparent paper),
each sketch optionally with a reference dictionary beside it (`NAME.json`, the tree the sketch was drawn from).
Subfolders are not read.

- A cloud goes through the cloud method (`reconstruct.from_cloud`): the share of its points within 10 cm of the
  reconstruction's bark and their median distance (AdTree's fit), the bark's height against the cloud's
  (`bark_height_rel_error`) and the share of its points the skeleton graph joined to the tree (connectedness).
- A sketch goes through the params method (TreeSketchNet): with a reference, species and levels right or wrong and
  the parameter score (Weber-Penn references); without one, the silhouette IoU of the result re-rendered in the
  sketch's view (tsn4 front), both outlines cut to their bounding boxes and compared at one height.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from farm.dataset import IMAGE_SUFFIXES, read_image
from renderers.silhouette_metric import closed_silhouette
from species.errors import user_path

from .methods import MethodContext, MethodResult, joined_share
from .units import EvaluationError, Unit

# reconstruct is imported where used: the package imports torch.

__all__ = ["input_units", "run_input", "SKETCH_SUFFIXES", "outline_iou"]

SKETCH_SUFFIXES = IMAGE_SUFFIXES
_IOU_SIZE = 128  # both outlines are compared at this size, cut to their bounding boxes
_INK = 128       # grey levels below this are strokes
_CLOSING_PX = 6  # gaps up to about twice this closed in a drawing's and a render's outline (at 224-256 px)


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


def outline_iou(mask_a: np.ndarray, mask_b: np.ndarray) -> float:
    """IoU of two outlines at one scale (a drawing has none): each cut to its bounding box and scaled to one
    height, keeping its aspect, both centred on one vertical axis (a tree's) on a shared canvas."""
    import cv2

    from reconstruct import metrics

    cut = []
    for mask in (mask_a, mask_b):
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        if rows.size == 0:
            return 0.0
        box = mask[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1].astype(np.uint8)
        width = max(1, int(round(box.shape[1] * _IOU_SIZE / box.shape[0])))
        cut.append(cv2.resize(box, (width, _IOU_SIZE), interpolation=cv2.INTER_NEAREST))
    canvas = max(c.shape[1] for c in cut)
    placed = [np.pad(c, ((0, 0), ((canvas - c.shape[1]) // 2, canvas - c.shape[1] - (canvas - c.shape[1]) // 2)))
              for c in cut]
    return metrics.silhouette_iou(*placed)


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
    from scipy.ndimage import binary_fill_holes

    net = ctx.net("sketchnet")
    image = read_image(str(path))
    result = reconstruct.from_params(image, net=net)
    start = time.perf_counter()
    camera = ctx.renderer.cameras(result.mesh, "tsn4", np.random.default_rng(0))[0]
    reference_path = path.with_suffix(".json")
    row: dict[str, float] = {}
    species = None
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
    else:
        grey = image if image.ndim == 2 else image.mean(axis=2)
        drawn = ctx.renderer.silhouette_masks(result.mesh, [camera])[0]
        # Outlines: a drawing's strokes and the rendered twigs and leaves closed into one filled shape each.
        ink, shape = (binary_fill_holes(closed_silhouette(m, _CLOSING_PX)) for m in (grey < _INK, drawn))
        row["silhouette_iou_input"] = outline_iou(ink, shape)
    cells = [("input", image), ("reconstruction", depth_picture(ctx.renderer, result.mesh, result.skeleton, camera))]
    return (MethodResult(row, {**result.timings, "scoring": time.perf_counter() - start}, cells,
                         {"sketchnet": net.source}), species)


def run_input(unit, ctx: MethodContext) -> tuple[MethodResult, str | None]:
    """Reconstruct and score one real input; returns (result, the reference's species or None)."""
    path = Path(unit.tree_id)
    return _run_cloud(path, ctx) if unit.method == "cloud" else _run_sketch(path, ctx)
