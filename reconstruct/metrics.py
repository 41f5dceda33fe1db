"""Metrics that judge a reconstruction against its ground truth: depth maps, skeletons, surfaces, silhouettes,
parameter dictionaries and tree measures.

In: numpy arrays, `Skeleton`s, `TreeMesh`es and Weber-Penn dictionaries. Out: floats and small frozen dataclasses;
every distance is dimensionless (divided by the tree height or the unit orthographic cube's side).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from scipy.spatial import cKDTree

from renderers.camera import ORTHO_MARGIN
from species.errors import TreefarmError
from species.geometry.vectors import column_bounds, row_norms
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh
from trainers.pix2pix import masked_depth_error
from trainers.sketchnet import height_crown_row
from trainers.sketchnet_codec import REGRESSION_HEADS, ParameterCodec

__all__ = ["MetricError", "PointSetDistances", "SkeletonMatch", "RADIUS_MULTIPLES", "DENSIFY_DIVISIONS",
           "SURFACE_SAMPLES", "foreground_depth_error", "node_distances", "unit_cube_hausdorff", "surface_distances",
           "point_set_distances", "image_plane_hausdorff", "skeleton_precision_recall", "bark_distances", "cloud_fit",
           "FIT_TOLERANCE_M", "silhouette_iou", "parameter_scores", "height_crown_errors"]

# The radius multiples t at which skeleton precision, recall and F1 are taken: 0, 0.01, ..., 1 (101 values); the
# area under the F1 curve is the trapezoid rule over them.
RADIUS_MULTIPLES = np.linspace(0.0, 1.0, 101)
# Skeletons are densified into points spaced at most (true tree height) / DENSIFY_DIVISIONS along each segment.
DENSIFY_DIVISIONS = 512
# Surface samples per mesh for `surface_distances` (digest 4.5: 100k per mesh).
SURFACE_SAMPLES = 100_000
# Distances at or below this fraction of the tree height count as zero: float32 positions round at ~6e-8 relative,
# so closer points are indistinguishable from touching (an identical copy then scores 1 at t = 0 too).
_ROUNDING = 1e-6
_SEGMENT_CANDIDATES = 8  # nearest samples whose segments are measured exactly (see `_nearest_on_segments`)


class MetricError(TreefarmError):
    """Input a metric cannot score: empty sets, mismatched shapes, NaN, a non-positive scale."""


# ------------------------------------------------------------------------------------------------ checks
def _points(value, name: str) -> np.ndarray:
    """(N, 3) float64 points of a Skeleton (its nodes) or an array; N >= 1 and finite, else MetricError."""
    if isinstance(value, Skeleton):
        return value.positions.astype(np.float64)
    points = _float_array(value, name)
    if points.ndim != 2 or points.shape[1] != 3:
        raise MetricError(f"{name} has shape {points.shape}: allowed a Skeleton or (N, 3) points")
    if len(points) == 0:
        raise MetricError(f"{name} is empty: allowed at least one point")
    if not np.isfinite(points).all():
        raise MetricError(f"{name} contains NaN or infinity: allowed finite points")
    return points


def _positive(value, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise MetricError(f"{name} = {value!r} is invalid: allowed a finite number > 0") from None
    if not (np.isfinite(number) and number > 0):
        raise MetricError(f"{name} = {value!r} is invalid: allowed a finite number > 0")
    return number


def _float_array(value, name: str) -> np.ndarray:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise MetricError(f"{name} of type {type(value).__name__} is not numeric: allowed a numeric array") from None


def _finite_array(value, name: str) -> np.ndarray:
    array = _float_array(value, name)
    if not np.isfinite(array).all():
        raise MetricError(f"{name} contains NaN or infinity: allowed finite values")
    return array


# ------------------------------------------------------------------------------------------------ depth
def foreground_depth_error(predicted, target, mask, channels: Sequence[int] | None = None,
                           up_to_mirror: bool = False) -> float:
    """Mean absolute error of [0, 1] depth over the foreground (mask > 0), pooled over the batch and the chosen
    channels: seed 000's depth metric (eq. 3.2 as a mean).

    predicted, target : (H, W), (C, H, W) or (B, C, H, W) arrays of one shape, depth01 (0 near, 1 far).
    mask              : (H, W), (1, H, W) or (B, 1, H, W), foreground where > 0, the same for every channel.
    channels          : the channels scored (default all; (C, H, W) and (B, C, H, W) inputs only).
    up_to_mirror      : the error against the target or its mirror through the view's middle plane (depth
                        1 - d), whichever is nearer: a tree and its mirror draw the same orthographic strokes, so
                        one drawing cannot tell them apart (benchmarks/bench_depth_bounds.py).
    """
    if up_to_mirror:
        mirrored = 1.0 - _finite_array(target, "target depth")
        return min(foreground_depth_error(predicted, target, mask, channels),
                   foreground_depth_error(predicted, mirrored, mask, channels))
    p, t = _finite_array(predicted, "predicted depth"), _finite_array(target, "target depth")
    if p.shape != t.shape or p.ndim not in (2, 3, 4):
        raise MetricError(f"predicted {p.shape} and target {t.shape} depth must share one shape: allowed (H, W), "
                          f"(C, H, W) or (B, C, H, W)")
    m = np.asarray(mask)
    if p.ndim == 2:
        if channels is not None:
            raise MetricError(f"channels {list(channels)} given for a single (H, W) map: allowed None")
        p, t = p[None, None], t[None, None]
        m = m[None, None] if m.ndim == 2 else m
    elif p.ndim == 3:
        p, t = p[None], t[None]
        m = m[None, None] if m.ndim == 2 else m[None]
    if m.shape != (p.shape[0], 1) + p.shape[2:]:
        raise MetricError(f"mask of shape {np.shape(mask)} does not fit depth of shape {np.shape(predicted)}: "
                          f"allowed (H, W), (1, H, W) or (B, 1, H, W) matching it")
    chosen = list(range(p.shape[1])) if channels is None else [int(c) for c in channels]
    if not chosen or any(not 0 <= c < p.shape[1] for c in chosen):
        raise MetricError(f"channels {chosen} are invalid for {p.shape[1]} depth channels: allowed indices in "
                          f"[0, {p.shape[1] - 1}]")
    foreground = _finite_array(m, "mask") > 0
    if not foreground.any():
        raise MetricError("the mask has no foreground pixel: allowed a mask with at least one value > 0")
    return masked_depth_error(p, t, foreground.astype(np.float64), chosen)  # the trainers' metric, one rule


# ------------------------------------------------------------------------------------------------ point sets
@dataclass(frozen=True)
class PointSetDistances:
    """Symmetric distances between two point sets, divided by a scale (a tree height or a cube side).

    hausdorff    : the larger of the two directed Hausdorff distances (max over each set of its nearest distance).
    hausdorff_95 : the same with the 95th percentile in place of the max (robust to a few stray points).
    chamfer      : the mean of the two directed mean nearest distances.
    """

    hausdorff: float
    hausdorff_95: float
    chamfer: float


def point_set_distances(a, b, scale: float) -> PointSetDistances:
    """Hausdorff, 95th-percentile Hausdorff and Chamfer distances between (N, 3) and (M, 3) points (or the node
    sets of two Skeletons), in metres divided by `scale` metres."""
    pa, pb = _points(a, "first point set"), _points(b, "second point set")
    scale = _positive(scale, "scale")
    a_to_b, _ = cKDTree(pb).query(pa)
    b_to_a, _ = cKDTree(pa).query(pb)
    return PointSetDistances(
        hausdorff=max(float(a_to_b.max()), float(b_to_a.max())) / scale,
        hausdorff_95=max(float(np.quantile(a_to_b, 0.95)), float(np.quantile(b_to_a, 0.95))) / scale,
        chamfer=0.5 * (float(a_to_b.mean()) + float(b_to_a.mean())) / scale)


def node_distances(a, b, height: float) -> PointSetDistances:
    """Distances between two skeletons' node sets (or any (N, 3) points), normalised by the tree height (metres,
    normally the ground truth's `Skeleton.height`)."""
    return point_set_distances(a, b, _positive(height, "height"))


def unit_cube_hausdorff(predicted, true, box: np.ndarray | None = None) -> float:
    """Symmetric Hausdorff distance between node sets inside the unit orthographic cube (digest 1.13).

    Both sets are scaled by the same box, the ground truth's: the orthographic volume the renderers fit to a tree
    (its bounding box plus ORTHO_MARGIN, one scale for every axis, as the square views use), mapped to the unit
    cube; the distance is then the metric one divided by that cube's side, (1 + margin) x the box's largest extent.

    predicted, true : Skeletons or (N, 3) points, metres.
    box             : (2, 3) min and max corners, metres; default the truth's `Skeleton.bounds` (nodes grown by
                      their radius and leaf corners: what the views were framed on), or its points' bounds.
    """
    truth = _points(true, "true node set")
    if box is None:
        box = true.bounds if isinstance(true, Skeleton) else np.stack(column_bounds(truth))
    box = _finite_array(box, "box")
    if box.shape != (2, 3) or np.any(box[1] < box[0]):
        raise MetricError(f"box of shape {box.shape} is invalid: allowed (2, 3) min and max corners, max >= min")
    extent = float((box[1] - box[0]).max())
    if extent <= 0:
        raise MetricError("the true node set spans no volume (a single point): the unit cube needs a box with a "
                          "positive extent; pass `box`")
    return point_set_distances(predicted, truth, (1.0 + ORTHO_MARGIN) * extent).hausdorff


def image_plane_hausdorff(predicted, true, camera) -> float:
    """Symmetric Hausdorff distance between two node sets seen in one view, inside the view's unit square: both
    projected to the camera's pixels, the distance divided by the image's longer side (the views are framed on
    the tree, so the square is the tree's). What a drawing fixes of its main branches: where they lie in the image
    plane, not their depth.

    predicted, true : Skeletons or (N, 3) points, metres.   camera : a `renderers.Camera` of that view.
    """
    planes = []
    for points, name in ((predicted, "predicted node set"), (true, "true node set")):
        pixels = camera.project(_points(points, name))[0]
        planes.append(np.column_stack([pixels, np.zeros(len(pixels))]))
    return point_set_distances(*planes, float(max(camera.width, camera.height))).hausdorff


def _surface_points(mesh: TreeMesh, n: int, rng: np.random.Generator, name: str) -> np.ndarray:
    """(n, 3) area-uniform samples of a tree's bark and leaves together (trimesh's sampler, drawing from rng)."""
    import trimesh

    if not isinstance(mesh, TreeMesh):
        raise MetricError(f"{name} is a {type(mesh).__name__}: allowed a species.TreeMesh")
    vertices = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices]).astype(np.float64)
    faces = np.concatenate([mesh.bark.faces, mesh.leaves.faces + mesh.bark.n_vertices])
    area = float(np.concatenate([mesh.bark.face_areas, mesh.leaves.face_areas]).sum()) if len(faces) else 0.0
    if area <= 0:
        raise MetricError(f"{name} has no surface ({len(faces)} triangles, area {area}): allowed a mesh with area")
    both = trimesh.Trimesh(vertices=vertices, faces=faces, process=False)
    points, _ = trimesh.sample.sample_surface(both, n, seed=rng)
    return points


def surface_distances(mesh_a: TreeMesh, mesh_b: TreeMesh, height: float, n: int,
                      rng: np.random.Generator) -> PointSetDistances:
    """Distances between `n` surface samples of each mesh (bark and leaves), normalised by the tree height
    (digest 4.5: the ground truth's height, n = SURFACE_SAMPLES). Samples are drawn from `rng`, mesh_a's first."""
    height = _positive(height, "height")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise MetricError(f"n = {n!r} surface samples is invalid: allowed an integer >= 1")
    if not isinstance(rng, np.random.Generator):
        raise MetricError(f"rng is a {type(rng).__name__}: allowed a numpy.random.Generator")
    a = _surface_points(mesh_a, int(n), rng, "mesh_a")
    b = _surface_points(mesh_b, int(n), rng, "mesh_b")
    return point_set_distances(a, b, height)


# ------------------------------------------------------------------------------------------------ skeletons
@dataclass(frozen=True, eq=False)
class _Densified:
    """A skeleton's segments (parent node -> node) and points along them, each carrying its interpolated radius.

    start, end     : (K, 3) float64 segment ends, metres; r_start, r_end : (K,) float64 radii there, metres.
    points         : (P, 3) float64 metres; radius (P,) metres; weight (P,) metres of branch each point stands
                     for (they sum to the total length); segment (P,) int64, the segment each point lies on.
    """

    start: np.ndarray
    end: np.ndarray
    r_start: np.ndarray
    r_end: np.ndarray
    points: np.ndarray
    radius: np.ndarray
    weight: np.ndarray
    segment: np.ndarray


def _densified(skeleton: Skeleton, spacing: float, name: str) -> _Densified:
    if not isinstance(skeleton, Skeleton):
        raise MetricError(f"{name} is a {type(skeleton).__name__}: allowed a species.Skeleton")
    if len(skeleton) < 2 or skeleton.total_length <= 0:
        raise MetricError(f"{name} has no branch length ({len(skeleton)} nodes, {skeleton.total_length} m): "
                          f"allowed a skeleton with at least one segment of positive length")
    parent = skeleton.parent[1:]
    pos, rad = skeleton.positions.astype(np.float64), skeleton.radius.astype(np.float64)
    start, end, r_start, r_end = pos[parent], pos[1:], rad[parent], rad[1:]
    length = row_norms(end - start)
    counts = np.maximum(1, np.ceil(length / spacing)).astype(np.int64)
    on = np.repeat(np.arange(len(length)), counts)
    first = np.cumsum(counts) - counts
    u = (np.arange(len(on)) - first[on] + 1) / counts[on]  # in (0, 1]: every node once, as a segment's end
    # The root joins as a point of no weight on segment 0 (which starts there: parent[1] = 0).
    return _Densified(
        start, end, r_start, r_end,
        points=np.concatenate([pos[:1], start[on] + u[:, None] * (end - start)[on]]),
        radius=np.concatenate([rad[:1], r_start[on] + u * (r_end - r_start)[on]]),
        weight=np.concatenate([[0.0], (length / counts)[on]]),
        segment=np.concatenate([[0], on]))


def _nearest_on_segments(query: np.ndarray, target: _Densified) -> tuple[np.ndarray, np.ndarray]:
    """(Q,) metres from each query point to the nearest of the target's segments, and (Q,) the target's radius at
    that nearest point. Segments are measured exactly for the few target points nearest each query: the nearest
    segment's closest point lies within spacing / 2 of one of its points, so a distance found is never more than
    spacing / 2 above the exact one, and is exact unless many segments crowd around the query."""
    k = min(_SEGMENT_CANDIDATES, len(target.points))
    _, index = cKDTree(target.points).query(query, k=k)
    segment = target.segment[index.reshape(len(query), k)]                     # (Q, k)
    a, d = target.start[segment], (target.end - target.start)[segment]
    dd = np.einsum("qkj,qkj->qk", d, d)
    u = np.clip(np.einsum("qkj,qkj->qk", query[:, None] - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    distance = row_norms(query[:, None] - (a + u[..., None] * d))
    rows, best = np.arange(len(query)), np.argmin(distance, axis=1)
    chosen, along = segment[rows, best], u[rows, best]
    radius = target.r_start[chosen] + along * (target.r_end[chosen] - target.r_start[chosen])
    return distance[rows, best], radius


def _matched_fraction(distance: np.ndarray, radius: np.ndarray, weight: np.ndarray, tolerance: float) -> np.ndarray:
    """(T,) the weighted fraction of points within t x radius (+ tolerance) at each t of RADIUS_MULTIPLES: the
    smallest t that matches a point is (distance - tolerance) / radius, so the curve is one weighted CDF."""
    needed = np.maximum(distance - tolerance, 0.0) / radius
    order = np.argsort(needed, kind="stable")
    cumulative = np.concatenate([[0.0], np.cumsum(weight[order])])
    matched = cumulative[np.searchsorted(needed[order], RADIUS_MULTIPLES, side="right")]
    return matched / cumulative[-1]


@dataclass(frozen=True, eq=False)
class SkeletonMatch:
    """Radius-scaled skeleton precision and recall (the Smart-Tree evaluator's protocol).

    thresholds : (T,) float64, the radius multiples t (RADIUS_MULTIPLES: 0 to 1 in steps of 0.01).
    precision  : (T,) fraction of the predicted skeleton's length within t x the true radius of the truth.
    recall     : (T,) fraction of the true skeleton's length within t x its own radius of the prediction.
    f1         : (T,) 2PR / (P + R), 0 where both are 0.
    auc        : area under f1 over t in [0, 1] (trapezoid rule over `thresholds`), in [0, 1].
    """

    thresholds: np.ndarray
    precision: np.ndarray
    recall: np.ndarray
    f1: np.ndarray
    auc: float


def skeleton_precision_recall(predicted: Skeleton, true: Skeleton, spacing: float | None = None) -> SkeletonMatch:
    """Precision, recall and F1 of a predicted skeleton against the true one, per radius multiple t, and the area
    under the F1 curve.

    Both skeletons are densified into points along their segments (at most `spacing` metres apart, default the
    true height / DENSIFY_DIVISIONS), each standing for its share of branch length and carrying the radius
    interpolated along its segment. A predicted point is a true positive at t when its distance to the true
    skeleton's segments is at most t x the true radius at the nearest true point; a true point is recalled when
    its distance to the predicted segments is at most t x its own radius. Both use the true radii, so a
    reconstruction cannot buy recall with thick branches. Distances below 1e-6 x the true height count as 0 (the
    rounding of float32 positions), so an identical skeleton scores 1 at every t, t = 0 included.
    """
    if not isinstance(true, Skeleton):
        raise MetricError(f"true is a {type(true).__name__}: allowed a species.Skeleton")
    height = _positive(true.height, "the true skeleton's height")
    spacing = height / DENSIFY_DIVISIONS if spacing is None else _positive(spacing, "spacing")
    pred_points, true_points = _densified(predicted, spacing, "predicted"), _densified(true, spacing, "true")
    tolerance = _ROUNDING * height
    to_true, true_radius = _nearest_on_segments(pred_points.points, true_points)
    to_pred, _ = _nearest_on_segments(true_points.points, pred_points)
    precision = _matched_fraction(to_true, true_radius, pred_points.weight, tolerance)
    recall = _matched_fraction(to_pred, true_points.radius, true_points.weight, tolerance)
    total = precision + recall
    f1 = np.divide(2 * precision * recall, total, out=np.zeros_like(total), where=total > 0)
    return SkeletonMatch(RADIUS_MULTIPLES.copy(), precision, recall, f1, float(np.trapezoid(f1, RADIUS_MULTIPLES)))


FIT_TOLERANCE_M = 0.10  # issue 24's bar: the bark within 10 cm of the cloud's points


def bark_distances(skeleton: Skeleton, points, spacing: float = 0.01) -> np.ndarray:
    """(P,) metres from each point to the skeleton's bark: |distance to the nearest segment's axis - the radius
    interpolated there| (a point inside a tube counts by how far it is from the wall). Segments are densified
    every `spacing` metres to find the nearest (see `_nearest_on_segments`)."""
    query = _points(points, "points")
    dense = _densified(skeleton, _positive(spacing, "spacing"), "skeleton")
    distance, radius = _nearest_on_segments(query, dense)
    return np.abs(distance - radius)


def cloud_fit(skeleton: Skeleton, points, tolerance: float = FIT_TOLERANCE_M) -> dict[str, float]:
    """How well a reconstruction's bark covers a cloud: the share of points within `tolerance` metres of it, and
    the median and 90th-percentile distances in metres (AdTree's measure of fit)."""
    distance = bark_distances(skeleton, points)
    return {"within": float((distance <= _positive(tolerance, "tolerance")).mean()),
            "median_m": float(np.median(distance)), "p90_m": float(np.percentile(distance, 90))}


# ------------------------------------------------------------------------------------------------ silhouettes
def silhouette_iou(mask_a, mask_b) -> float:
    """Intersection over union of two foreground masks of one shape (foreground: values > 0; bool, 0/1 or 0/255
    alike), pooled over every pixel (stack views on a leading axis to pool them)."""
    a, b = _finite_array(mask_a, "mask_a"), _finite_array(mask_b, "mask_b")
    if a.shape != b.shape or a.size == 0:
        raise MetricError(f"masks of shapes {a.shape} and {b.shape} cannot be compared: allowed two non-empty masks "
                          f"of one shape")
    a, b = a > 0, b > 0
    union = int(np.count_nonzero(a | b))
    if union == 0:
        raise MetricError("both masks are empty: the IoU needs a foreground pixel in at least one")
    return np.count_nonzero(a & b) / union


# ------------------------------------------------------------------------------------------------ parameters
def parameter_scores(codec: ParameterCodec, predicted: Mapping | Sequence[Mapping],
                     true: Mapping | Sequence[Mapping]) -> dict[str, float]:
    """TreeSketchNet's score, (1 - RMSE) x 100 on the codec's normalised values, per regression head
    (`score_HEAD`) and over all of them (`score_overall`), pooled over the dictionaries: the rule of
    `trainers.sketchnet.sketchnet_metrics`, applied to two dictionaries encoded by the same codec.

    Values are compared where the true dictionary uses them (its levels, its draws: the codec's target mask),
    as the network's outputs are; a predicted dictionary's absent draws count as the codec encodes them.
    """
    predicted = [predicted] if isinstance(predicted, Mapping) else list(predicted)
    true = [true] if isinstance(true, Mapping) else list(true)
    if len(predicted) != len(true) or not true:
        raise MetricError(f"parameter_scores needs as many predicted as true dictionaries (at least one); got "
                          f"{len(predicted)} and {len(true)}")
    guess, truth = codec.encode_arrays(predicted, np.float64), codec.encode_arrays(true, np.float64)
    scores: dict[str, float] = {}
    total_squares = total_count = 0.0
    for head in REGRESSION_HEADS:
        mask = truth[f"{head}_mask"] > 0
        squares, count = float(((guess[head] - truth[head])[mask] ** 2).sum()), float(mask.sum())
        total_squares, total_count = total_squares + squares, total_count + count
        scores[f"score_{head}"] = 100.0 * (1.0 - np.sqrt(squares / max(count, 1.0)))
    scores["score_overall"] = 100.0 * (1.0 - np.sqrt(total_squares / max(total_count, 1.0)))
    return scores


# ------------------------------------------------------------------------------------------------ measures
def height_crown_errors(skel_pred: Skeleton, skel_true: Skeleton) -> dict[str, float]:
    """Height and crown radius (metres, `Skeleton.height` / `.crown_radius`) of both skeletons and the relative
    errors |pred - true| / true: keys `height`, `true_height`, `height_rel_error` and the same for `crown_radius`
    (the per-tree row of `trainers.sketchnet.grown_tree_errors`)."""
    for name, skeleton in (("skel_pred", skel_pred), ("skel_true", skel_true)):
        if not isinstance(skeleton, Skeleton):
            raise MetricError(f"{name} is a {type(skeleton).__name__}: allowed a species.Skeleton")
    for measure in ("height", "crown_radius"):
        reference = float(getattr(skel_true, measure))
        if not reference > 0:
            raise MetricError(f"the true skeleton's {measure} is {reference} m: a relative error needs a true "
                              f"{measure} > 0")
    return height_crown_row(skel_pred, skel_true)
