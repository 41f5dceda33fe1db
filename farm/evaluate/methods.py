"""How the evaluation runs the reconstruction methods of `reconstruct.methods.METHODS` (the one registry) on a
held-out tree, what each needs from a dataset, and how each is scored.

A method reads one held-out tree (`HeldOutTree`: the true dictionary, skeleton and mesh, and the dataset's views
of it) and returns a `MethodResult`: metric values (`reconstruct.scoring.METRICS` names), stage seconds, and the
gallery panel's cells (input, reconstruction and ground truth in the input view). Alignment follows
`benchmarks/bench_reconstruct.py`: every tree stands with its base at the origin, Z up, in metres; a drawing has no
scale, so the sketch methods grow at the true height (two-view: the top of the true main branches, what the strokes
span).

A method runs by the kind of what it reads, and three add what the evaluation knows of them (`RUNNERS`):
- drawings (`run_drawn`): its inputs from the views the registry names (`Input.rendered`), its networks loaded once
  per worker, the tree's seed, the true height, the fit budget (`EvalSettings.fit_evals`), and the geometry metrics
  in its input views; a method that fitted its tree (a `FitRecord` in its maps) shows the fit's outlines.
  - params (seed 004): TreeSketchNet reads the `tsn4` front view's `sketch_tsn`, with the dictionary's seed 0;
    species, levels and the parameter score (Weber-Penn trees only: the codec's dictionaries) beside the geometry.
  - sketch-depth (seed 000): the `two-view` front view's `sketch_edges` and `trunk_strokes` through both pix2pix
    networks; with `silhouette_envelope` / `trunk_depth` stored, the networks' foreground depth errors too.
  - two-view (seed 001): the `two-view:shared` front and side `sketch_strokes`, 1-pixel lines.
- a point cloud (`run_scan`, the cloud method, seed 003): a synthetic scan of the true mesh
  (`reconstruct.cloud_sampling`: leaf clutter, outliers, an occlusion wedge, seeded per tree); also the scan's fit
  to the bark and the connectedness.
- photos (`run_orbit`, the photos method, SfM): a leafless orbit rendered with Blender (Cycles), reconstructed at the
  cameras' known poses.
"""
from __future__ import annotations

import dataclasses
import functools
import hashlib
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, Sequence

import numpy as np

from farm.dataset import read_image
from reconstruct.cloud_sampling import WOOD, sample_tree_cloud
from reconstruct.fit_budget import DEFAULT_FIT_EVALS
from reconstruct.methods import METHODS as RECONSTRUCTION_METHODS
from reconstruct.methods import RunOptions, get_method
from reconstruct.report import cloud_drawing
from renderers import Camera, ViewRenderer
from renderers.blender import render_photos
from renderers.camera import parse_rig, perspective_camera
from species.errors import TreefarmError
from species.skeleton import Skeleton
from species.tree_mesh import MeshPart, TreeMesh

# reconstruct.metrics and reconstruct.scoring are imported where used: both import torch, which planning an
# evaluation (`farm evaluate --print-data-spec`, the command's checks) does not need.
if TYPE_CHECKING:  # reconstruct.fitting imports scipy, which the command's checks do not need (start-up time)
    from reconstruct.fitting import FitRecord

__all__ = ["METHODS", "Method", "Needs", "HeldOutTree", "MethodResult", "EvalSettings", "MethodContext",
           "tree_rng_seed", "joined_share", "needs_of", "run_drawn", "run_method", "fit_cells"]


@dataclass(frozen=True)
class Needs:
    """The views a method reads: `views` of rig `rig` holding `outputs` (`optional` ones scored when stored);
    `rig` None: the method makes its own input from the true tree."""

    rig: str | None = None
    views: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()


@dataclass
class HeldOutTree:
    """One tree to reconstruct: where it comes from, its truth, and its views (name -> (camera, images))."""

    dataset: str
    spec_digest: str
    tree_id: str
    species: str
    params: dict
    skeleton: Skeleton
    mesh: TreeMesh
    views: dict[str, tuple[Camera, dict[str, np.ndarray]]] = field(default_factory=dict)


@dataclass
class MethodResult:
    metrics: dict[str, float]
    timings: dict[str, float]
    cells: list[tuple[str, np.ndarray]]
    models: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class EvalSettings:
    """How the evaluation measures: surface samples per mesh (0: no surface distances), the synthetic scan, the
    photos' orbit (views 10 deg apart, leafless: digest and docs/reconstruct.md say why), and the drawing methods'
    fit to their drawings (`RunOptions.fit_evals`: candidate trees per drawing; 0: each method's first guess)."""

    surface_samples: int = 20_000
    cloud_points: int = 20_000
    cloud_leaf_fraction: float = 0.2
    cloud_outlier_fraction: float = 0.02
    cloud_wedge_deg: float = 30.0
    photo_views: int = 10
    photo_size: int = 400
    photo_samples: int = 4
    seed: int = 0
    fit_evals: int = DEFAULT_FIT_EVALS


class MethodContext:
    """What a worker keeps between trees: one offscreen renderer and the networks, loaded on first use."""

    def __init__(self, models: str | None, settings: EvalSettings, size: int = 256):
        self.models, self.settings = models, settings
        self.renderer = ViewRenderer(size)
        self._nets: dict[str, object] = {}

    def net(self, task: str):
        if task not in self._nets:
            from reconstruct.networks import predictor

            self._nets[task] = predictor(task, self.models)
        return self._nets[task]

    def nets(self, tasks: Sequence[str]) -> dict[str, object]:
        return {task: self.net(task) for task in tasks}

    def close(self) -> None:
        self.renderer.close()


@dataclass(frozen=True)
class Method:
    """A registry method as the evaluation runs it."""

    name: str
    needs: Needs
    run: Callable[[HeldOutTree, MethodContext], MethodResult]
    models: tuple[str, ...] = ()  # the trained networks it uses (trainers task names)
    description: str = ""


def tree_rng_seed(tree: HeldOutTree, method: str, seed: int) -> int:
    """A method's seed for one tree: sha256 of (seed, method, spec digest, tree id), so a tree draws the same
    scan, growth and phyllotaxis whichever worker takes it and whatever else the job holds."""
    text = f"{seed}/{method}/{tree.spec_digest}/{tree.tree_id}".encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:8], "big")


def joined_share(result) -> float:
    """The share of a cloud's points its skeleton graph joined to the tree (a skeleton is one tree by
    construction, so connectedness is what the graph reached: `CloudSkeleton.n_reached / n_used`)."""
    return float(result.scan.fit.n_reached) / max(1, int(result.scan.fit.n_used))


def _scorer(ctx: MethodContext, tree: HeldOutTree, cameras, seen_azimuths):
    from reconstruct.scoring import TreeScorer

    return TreeScorer(ctx.renderer, tree.skeleton, tree.mesh, cameras, seen_azimuths, ctx.settings.surface_samples)


def _pictures(ctx: MethodContext, tree: HeldOutTree, camera: Camera, skeleton: Skeleton,
              mesh: TreeMesh) -> list[tuple[str, np.ndarray]]:
    from reconstruct.scoring import depth_picture

    return [("reconstruction", depth_picture(ctx.renderer, mesh, skeleton, camera)),
            ("ground truth", depth_picture(ctx.renderer, tree.mesh, tree.skeleton, camera))]


# ------------------------------------------------------------------------------------------------ drawn inputs
def _square(picture: np.ndarray) -> np.ndarray:
    """An (H, W, 3) picture padded with black to a square, so a panel's cell does not stretch it."""
    side = max(picture.shape[:2])
    rows, cols = side - picture.shape[0], side - picture.shape[1]
    return np.pad(picture, ((rows // 2, rows - rows // 2), (cols // 2, cols - cols // 2), (0, 0)))


def fit_cells(record: FitRecord) -> list[tuple[str, np.ndarray]]:
    """Panel cells of a fit (`reconstruct.fitting.FitRecord`): the drawing's outline (green) under the first
    guess's and the result's (red; both yellow), each labelled with its outline IoU; one cell when the record holds
    no evaluations (a result scored, not fitted)."""
    return [(label, _square(picture)) for label, picture in record.panels()]


# What a drawn method's extra metrics are made from: (its result, its networks by task, the tree's views).
ExtraMetrics = Callable[[object, dict, dict], dict]


def run_drawn(name: str, tree: HeldOutTree, ctx: MethodContext, *, seed: int | None = None,
              height: float | None = None, labels: Sequence[str] = (), extra: ExtraMetrics | None = None,
              **options) -> MethodResult:
    """A registry method whose inputs are rendered drawings, on one tree: its inputs from the tree's views (the
    registry's `Input.rendered`), its networks, the tree's seed (`tree_rng_seed`, unless `seed`), the true height
    (unless `height`), the settings' fit budget (`EvalSettings.fit_evals`), the worker's renderer for the fit and
    `options` (RunOptions fields); scored with the geometry metrics in its input views (`main_skeleton` from its
    maps), then `extra`'s metrics. Cells: its inputs (`labels`, default "input" or "input NAME"), the fit's
    outlines where it fitted, then the reconstruction and the truth in its first input view."""
    method = get_method(name)
    needs = needs_of(name)
    inputs = {item.name: tree.views[item.rendered.view][1][item.rendered.output] for item in method.reads}
    cameras = [tree.views[view][0] for view in needs.views]
    azimuths = [azimuth for view, azimuth, _ in parse_rig(needs.rig).views if view in needs.views]
    nets = ctx.nets(method.models)
    seed = tree_rng_seed(tree, name, ctx.settings.seed) if seed is None else seed
    start = time.perf_counter()
    options = {"fit_evals": ctx.settings.fit_evals, "renderer": ctx.renderer, **options}
    result = method.run(inputs, RunOptions(seed=seed, height=tree.skeleton.height if height is None else height,
                                           nets=nets, **options))
    timings = {**result.timings}
    timings.setdefault("total", time.perf_counter() - start)
    start = time.perf_counter()
    row = _scorer(ctx, tree, cameras, azimuths)(result.skeleton, result.mesh, result.maps.get("main_skeleton"))
    if extra is not None:
        row.update(extra(result, nets, {view: images for view, (_, images) in tree.views.items()}))
    timings["scoring"] = time.perf_counter() - start
    labels = labels or (["input"] if len(inputs) == 1 else [f"input {key}" for key in inputs])
    fit = result.maps.get("fit")  # a reconstruct.fitting.FitRecord where the method fitted its tree
    cells = [*zip(labels, inputs.values()), *(fit_cells(fit) if fit is not None else []),
             *_pictures(ctx, tree, cameras[0], result.skeleton, result.mesh)]
    return MethodResult(row, timings, cells, {task: net.source for task, net in nets.items()})


def run_params(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    from reconstruct import metrics

    def extra(result, nets, views) -> dict:
        codec, row = nets["sketchnet"].codec, {}
        if tree.species in codec.species:  # a species the network can name
            row["species_correct"] = float(result.params.get("species") == tree.species)
        if tree.params.get("generator", "weber_penn") == "weber_penn":
            row["levels_correct"] = float(int(result.params.get("levels", -1)) == int(tree.params.get("levels", -2)))
            row["param_score"] = metrics.parameter_scores(codec, result.params, tree.params)["score_overall"]
        return row

    # seed 0: the dictionary's own, as a user's run
    return run_drawn("params", tree, ctx, seed=0, extra=extra)


def run_sketch_depth(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    from reconstruct.scoring import network_depth_error

    def extra(result, nets, views) -> dict:
        images, row = views["front"], {}
        if "silhouette_envelope" in images:
            row["depth_error_silhouette"] = network_depth_error(nets["pix2pix-silhouette"], "silhouette", images)[0]
        if "trunk_depth" in images:
            row["depth_error_trunk"] = network_depth_error(nets["pix2pix-trunk"], "trunk", images)[0]
            row["depth_error_trunk_mirror"] = network_depth_error(nets["pix2pix-trunk"], "trunk", images,
                                                                  up_to_mirror=True)[0]
        return row

    return run_drawn("sketch-depth", tree, ctx, labels=("input", "trunk strokes"), extra=extra)


def run_two_view(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    from reconstruct.scoring import main_branch_nodes

    # The strokes draw the main branches only, in 1-pixel lines.
    return run_drawn("two-view", tree, ctx, height=float(main_branch_nodes(tree.skeleton)[:, 2].max()), brush=False)


# ------------------------------------------------------------------------------------------------ scans
def _cloud_scores(ctx: MethodContext, tree: HeldOutTree, result, points: np.ndarray) -> dict[str, float]:
    """Geometry against the true tree and the fit to `points` (the scan's own coordinates)."""
    from reconstruct import metrics

    skeleton, mesh = result.in_scan_frame()  # the true tree's frame, which the scan was sampled in
    row = _scorer(ctx, tree, [], ())(skeleton, mesh)
    fit = metrics.cloud_fit(skeleton, points)
    row.update({"cloud_fit_10cm": fit["within"], "cloud_fit_median_m": fit["median_m"],
                "joined_share": joined_share(result)})
    return row


def _front_camera(ctx: MethodContext, tree: HeldOutTree) -> Camera:
    return ctx.renderer.cameras(tree.mesh, "tsn4", np.random.default_rng(0))[0]


def run_scan(name: str, tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    """A registry method that reads a point cloud, on a synthetic scan of the true tree (module docstring)."""
    s = ctx.settings
    seed = tree_rng_seed(tree, name, s.seed)
    start = time.perf_counter()
    leaf = s.cloud_leaf_fraction if tree.mesh.leaves.n_faces else 0.0
    scan = sample_tree_cloud(tree.mesh, np.random.default_rng(seed), n_points=s.cloud_points, leaf_fraction=leaf,
                             outlier_fraction=s.cloud_outlier_fraction, occlusion_wedge_deg=s.cloud_wedge_deg)
    sampling = time.perf_counter() - start
    method = get_method(name)
    result = method.run({method.reads[0].name: scan.points}, RunOptions(seed=seed % 2**32))
    start = time.perf_counter()
    row = _cloud_scores(ctx, tree, result, scan.points[scan.labels == WOOD])
    timings = {"scan": sampling, **result.timings, "scoring": time.perf_counter() - start}
    cells = [("input scan", cloud_drawing(scan.points, 0)),
             *_pictures(ctx, tree, _front_camera(ctx, tree), *result.in_scan_frame())]
    return MethodResult(row, timings, cells)


def run_orbit(name: str, tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    """A registry method that reads photos, on a leafless Blender orbit of the true tree at known poses."""
    s = ctx.settings
    seed = tree_rng_seed(tree, name, s.seed) % 2**31
    leafless = dataclasses.replace(tree.mesh, leaves=MeshPart.empty())
    points = leafless.bark.vertices
    cameras = [perspective_camera(points, k * 10.0, 15.0 if k % 2 else 8.0, s.photo_size, name=f"view{k}")
               for k in range(s.photo_views)]
    with tempfile.TemporaryDirectory(prefix="treefarm-eval-photos-") as folder:
        start = time.perf_counter()
        photos = render_photos(leafless.to_glb(), cameras, Path(folder) / "photos", samples=s.photo_samples)
        rendering = time.perf_counter() - start
        first = read_image(photos.images[0])
        method = get_method(name)
        result = method.run({method.reads[0].name: Path(folder) / "photos"},
                            RunOptions(seed=seed, poses="known", threads=1, workdir=Path(folder) / "sfm"))
    start = time.perf_counter()
    bare = dataclasses.replace(tree, mesh=leafless)
    transform = result.scan.transform
    in_world = result.scan.base_points @ transform[:3, :3].T + transform[:3, 3]  # the renders' frame
    row = _cloud_scores(ctx, bare, result, in_world)
    timings = {"photos (Cycles)": rendering, **result.timings, "scoring": time.perf_counter() - start}
    cells = [("input photo", first), *_pictures(ctx, bare, _front_camera(ctx, bare), *result.in_scan_frame())]
    return MethodResult(row, timings, cells)


# ------------------------------------------------------------------------------------------------ the registry
# What the evaluation knows of a method beyond its registry entry: how it feeds and scores it. Every other method
# runs as `run_drawn` when every input is a rendered drawing, or by the kind of its one input (KIND_RUNNERS).
RUNNERS: dict[str, Callable[[HeldOutTree, MethodContext], MethodResult]] = {
    "params": run_params, "sketch-depth": run_sketch_depth, "two-view": run_two_view}
KIND_RUNNERS: dict[str, Callable[[str, HeldOutTree, MethodContext], MethodResult]] = {
    "cloud": run_scan, "photos": run_orbit}
# Outputs a method is scored on when a dataset stores them (beside the inputs the registry names).
SCORED_OUTPUTS = {"sketch-depth": ("silhouette_envelope", "trunk_depth")}


def needs_of(name: str) -> Needs:
    """The views a registry method reads from a dataset: its inputs' `rendered` outputs (all of one rig), or none
    for a method whose inputs the evaluation makes from the true tree."""
    rendered = [item.rendered for item in get_method(name).reads if item.rendered is not None]
    if not rendered:
        return Needs()
    return Needs(rendered[0].rig, tuple(dict.fromkeys(r.view for r in rendered)),
                 tuple(dict.fromkeys(r.output for r in rendered)), SCORED_OUTPUTS.get(name, ()))


def _runner(name: str) -> Callable[[HeldOutTree, MethodContext], MethodResult]:
    if name in RUNNERS:
        return RUNNERS[name]
    reads = get_method(name).reads
    if all(item.kind == "image" and item.rendered is not None for item in reads):
        return functools.partial(run_drawn, name)
    if len(reads) == 1 and reads[0].kind in KIND_RUNNERS:
        return functools.partial(KIND_RUNNERS[reads[0].kind], name)

    def unsupported(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
        raise TreefarmError(f"method {name!r}: the evaluation makes drawings the registry names a rendered output "
                            "for, one scan or one set of photos, not its inputs")

    return unsupported


class _EvaluatedMethods(Mapping):
    """The registry's methods as the evaluation runs them, read from `reconstruct.methods.METHODS` on each use."""

    def __getitem__(self, name: str) -> Method:
        method = RECONSTRUCTION_METHODS[name]
        return Method(name, needs_of(name), _runner(name), method.models, method.summary)

    def __iter__(self) -> Iterator[str]:
        return iter(RECONSTRUCTION_METHODS)

    def __len__(self) -> int:
        return len(RECONSTRUCTION_METHODS)


METHODS: Mapping[str, Method] = _EvaluatedMethods()


def run_method(method: str, tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    """Run one method on one tree; TreefarmErrors (a tree the method cannot reconstruct) propagate."""
    if method not in METHODS:
        raise TreefarmError(f"unknown method {method!r}: allowed {', '.join(METHODS)}")
    return METHODS[method].run(tree, ctx)
