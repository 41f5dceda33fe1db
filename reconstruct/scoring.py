"""One reconstruction scored against its ground-truth tree with every geometry metric of `reconstruct.metrics`,
and the catalogue of metric names the evaluation job, its summary and `compare` share.

`TreeScorer(renderer, skeleton, mesh, input_cameras, seen_azimuths)` renders the true tree's silhouettes once (in
the input views and in the unseen views: azimuths of rig UNSEEN_RIG, 45 deg apart, that no input looked along or
opposite), then scores any number of reconstructions of it: silhouette and crown IoU in both sets of views, node
Hausdorff / Chamfer over the true height, node Hausdorff in the unit orthographic cube, surface distances (when
`surface_samples` > 0), the skeleton F1 AUC, height and crown errors and, given the main-branch nodes, the main
skeleton's unit-cube Hausdorff and its Hausdorff in the input views' image planes. The keys are METRICS' names.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from renderers import Camera, ViewRenderer, main_branches, viewable
from renderers.silhouette_metric import closed_silhouette
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh
from trainers.data import TARGET_BACKGROUND
from trainers.pix2pix import targets_from_views
from trainers.preprocess import apply_crop
from trainers.tasks import get_task

from . import metrics

__all__ = ["TreeScorer", "Metric", "METRICS", "UNSEEN_RIG", "CROWN_CLOSING_PX", "main_branch_nodes",
           "main_branch_points", "crowns", "depth_picture", "network_depth_error"]

# Unseen views: azimuths of this rig (45 deg apart, level) that no input view looked along (or opposite).
UNSEEN_RIG = "orbit:8:0"
# Silhouettes of twigs and leaf cards overlap only where two trees agree to the pixel; the crown IoU compares the
# outlines, closed over gaps up to about twice this many pixels (at 256 px: the crown, not its twigs).
CROWN_CLOSING_PX = 6


@dataclass(frozen=True)
class Metric:
    """A metric column: what it is, which way is better, and the papers' figure beside ours ("" where none is
    published; `paper_method`: the one method the figure is about, "" for every method)."""

    label: str
    higher_is_better: bool
    paper: str = ""
    paper_method: str = ""


METRICS: dict[str, Metric] = {
    "silhouette_iou_input": Metric("silhouette IoU, input views", True),
    "crown_iou_input": Metric("crown IoU, input views", True),
    "silhouette_iou_unseen": Metric("silhouette IoU, unseen views", True),
    "crown_iou_unseen": Metric("crown IoU, unseen views", True),
    "node_hausdorff": Metric("node Hausdorff / height", False),
    "node_hausdorff95": Metric("node Hausdorff95 / height", False),
    "node_chamfer": Metric("node Chamfer / height", False),
    "unit_cube_hausdorff": Metric("nodes, unit-cube Hausdorff", False, "~0.03 (TSN rotation test, one tree)",
                                  "params"),
    "surface_hausdorff": Metric("surface Hausdorff / height", False, "TSN HDD: values n.g.", "params"),
    "surface_chamfer": Metric("surface Chamfer / height", False),
    "skeleton_f1_auc": Metric("skeleton F1 AUC", True),
    "height_rel_error": Metric("height rel. error", False),
    "crown_radius_rel_error": Metric("crown radius rel. error", False),
    "main_skeleton_unit_cube_hausdorff": Metric("main skeleton, unit-cube Hausdorff", False,
                                                "0.098 (thesis, trunk nodes, units n.g.)", "sketch-depth"),
    "main_skeleton_view_hausdorff": Metric("main skeleton, input-view Hausdorff", False),
    "depth_error_silhouette": Metric("depth error, silhouette network", False, "0.041 (thesis, GTX 1080 Ti)",
                                     "sketch-depth"),
    "depth_error_trunk": Metric("depth error, trunk network", False, "0.032 (thesis)", "sketch-depth"),
    "depth_error_trunk_mirror": Metric("trunk depth error, up to mirror", False,
                                       "0.127 for a constant 0.5 (bench_depth_bounds)", "sketch-depth"),
    "species_correct": Metric("species accuracy", True, "n.g. (bench_train target >= 0.95)", "params"),
    "levels_correct": Metric("levels accuracy", True),
    "param_score": Metric("parameter score (1 - RMSE) x 100", True, "n.g. (TSN tables are images)", "params"),
    "cloud_fit_10cm": Metric("share of points within 10 cm of the bark", True,
                             "AdTree: 0.99 on tree1 (bench_reconstruct_cloud)", "cloud"),
    "cloud_fit_median_m": Metric("median point-to-bark distance, m", False),
    "bark_height_rel_error": Metric("bark height vs cloud height, rel. error", False),
    "joined_share": Metric("share of points joined to the tree graph", True),
    "rotation_sweep_unit_cube_hausdorff": Metric("rotation sweep, unit-cube Hausdorff", False,
                                                 "~0.03 (TSN, 72 views, one unseen tree)", "params"),
}


def main_branch_nodes(skeleton: Skeleton) -> np.ndarray:
    """(K, 3) float32 metres: the nodes of a tree's main branches (`renderers.main_branches`: what the strokes
    draw), the set a traced or lifted main skeleton is compared with."""
    return skeleton.positions[_main_branch_indices(skeleton)]


def _main_branch_indices(skeleton: Skeleton) -> np.ndarray:
    """Sorted node indices of the main branches (`renderers.main_branches`)."""
    paths = skeleton.branch_paths
    return np.unique(np.concatenate([paths[int(b)] for b in main_branches(skeleton)]))


def main_branch_points(skeleton: Skeleton, divisions: int = metrics.DENSIFY_DIVISIONS) -> np.ndarray:
    """(K, 3) float64 metres: points along the main branches' segments (`main_branch_nodes`' edges, each branch
    joined to its parent node), at most height / divisions apart: the drawn curves, not only their nodes."""
    child = _main_branch_indices(skeleton)
    child = child[skeleton.parent[child] >= 0]
    start = skeleton.positions[skeleton.parent[child]].astype(np.float64)
    end = skeleton.positions[child].astype(np.float64)
    spacing = max(float(skeleton.height), 1e-9) / divisions
    steps = np.maximum(np.ceil(np.linalg.norm(end - start, axis=1) / spacing).astype(np.int64), 1)
    segment = np.repeat(np.arange(len(child)), steps)
    t = (np.arange(len(segment)) - np.repeat(np.cumsum(steps) - steps, steps)) / steps[segment]
    inner = start[segment] + t[:, None] * (end[segment] - start[segment])
    return np.concatenate([inner, end, skeleton.positions[:1].astype(np.float64)])


def crowns(masks: np.ndarray) -> np.ndarray:
    """(V, H, W) bool crown outlines of silhouette masks: gaps up to ~2 x CROWN_CLOSING_PX closed."""
    return np.stack([closed_silhouette(m, CROWN_CLOSING_PX) for m in masks])


class TreeScorer:
    """Geometry metrics of reconstructions of one true tree, its silhouettes rendered once (module docstring)."""

    def __init__(self, renderer: ViewRenderer, skeleton: Skeleton, mesh: TreeMesh, input_cameras: Sequence[Camera],
                 seen_azimuths: Sequence[float], surface_samples: int = 0):
        self.renderer, self.skeleton, self.mesh = renderer, skeleton, mesh
        self.surface_samples = int(surface_samples)
        orbit = renderer.cameras(mesh, UNSEEN_RIG, np.random.default_rng(0))
        step = 360 // len(orbit)
        seen = {round(float(a)) % 360 for a in seen_azimuths}
        self.cameras = {"input": list(input_cameras),
                        "unseen": [c for i, c in enumerate(orbit) if (i * step) % 360 not in seen
                                   and (i * step + 180) % 360 not in seen]}
        self.masks = {k: renderer.silhouette_masks(mesh, cams) for k, cams in self.cameras.items() if cams}
        self.crowns = {k: crowns(m) for k, m in self.masks.items()}
        self.main_nodes = main_branch_nodes(skeleton)
        self.main_points = main_branch_points(skeleton)

    def __call__(self, skeleton: Skeleton, mesh: TreeMesh, main_nodes: np.ndarray | None = None) -> dict[str, float]:
        truth, height = self.skeleton, self.skeleton.height
        row: dict[str, float] = {}
        for kind, true_masks in self.masks.items():
            masks = self.renderer.silhouette_masks(mesh, self.cameras[kind])
            row[f"silhouette_iou_{kind}"] = metrics.silhouette_iou(masks, true_masks)
            row[f"crown_iou_{kind}"] = metrics.silhouette_iou(crowns(masks), self.crowns[kind])
        nodes = metrics.node_distances(skeleton, truth, height)
        row.update({"node_hausdorff": nodes.hausdorff, "node_hausdorff95": nodes.hausdorff_95,
                    "node_chamfer": nodes.chamfer, "unit_cube_hausdorff": metrics.unit_cube_hausdorff(skeleton, truth)})
        if self.surface_samples:
            surface = metrics.surface_distances(mesh, self.mesh, height, self.surface_samples,
                                                np.random.default_rng(0))
            row.update({"surface_hausdorff": surface.hausdorff, "surface_chamfer": surface.chamfer})
        row["skeleton_f1_auc"] = metrics.skeleton_precision_recall(skeleton, truth).auc
        errors = metrics.height_crown_errors(skeleton, truth)
        row.update({"height_rel_error": errors["height_rel_error"],
                    "crown_radius_rel_error": errors["crown_radius_rel_error"]})
        if main_nodes is not None:
            row["main_skeleton_unit_cube_hausdorff"] = metrics.unit_cube_hausdorff(main_nodes, self.main_nodes,
                                                                                   box=truth.bounds)
            row["main_skeleton_view_hausdorff"] = float(np.mean([
                metrics.image_plane_hausdorff(main_nodes, self.main_points, camera)
                for camera in self.cameras["input"]]))
        return {k: float(v) for k, v in row.items()}


def depth_picture(renderer: ViewRenderer, mesh: TreeMesh, skeleton: Skeleton, camera: Camera) -> np.ndarray:
    """(H, W, 3) uint8 shaded depth of a tree in a camera, for galleries and contact sheets (black where nothing
    is, and for a tree with no faces)."""

    if mesh.n_faces == 0:
        return np.zeros((camera.height, camera.width, 3), np.uint8)
    view = renderer.render_cameras(mesh, skeleton, [camera], ["depth"], np.random.default_rng(0))[0]
    return viewable("depth", view.images["depth"])


def network_depth_error(net, task_name: str, images: dict, up_to_mirror: bool = False) -> tuple[float, float]:
    """(foreground depth error of a pix2pix network on one view's images, the network's seconds): the target cut
    to the network's crop of its input as training cut it, scored on the task's depth channels and mask rule
    (`up_to_mirror`: against the target or its mirror, `metrics.foreground_depth_error`)."""

    task = get_task(f"pix2pix-{task_name}")
    source, target_name = task.inputs[0], task.targets[0]
    start = time.perf_counter()
    prediction, prepared = net.predict_view(images[source])
    seconds = time.perf_counter() - start
    size = net.input_size
    cut = {source: apply_crop(images[source], prepared.crop, size, 255),
           target_name: apply_crop(images[target_name], prepared.crop, size, TARGET_BACKGROUND[target_name])}
    cut = {k: v[None] if v.ndim == 2 else np.moveaxis(v, 2, 0) for k, v in cut.items()}
    _, target, mask = targets_from_views(task, cut)
    return metrics.foreground_depth_error(prediction, target.numpy(), mask.numpy(), task.depth_channels,
                                          up_to_mirror), seconds
