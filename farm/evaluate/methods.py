"""The reconstruction methods an evaluation runs, what each needs from a dataset, and how each is scored.

A method reads one held-out tree (`HeldOutTree`: the true dictionary, skeleton and mesh, and the dataset's views
of it) and returns a `MethodResult`: metric values (`reconstruct.scoring.METRICS` names), stage seconds, and the
gallery panel's cells (input, reconstruction and ground truth in the input view). Alignment follows
`benchmarks/bench_reconstruct.py`: every tree stands with its base at the origin, Z up, in metres; a drawing has no
scale, so the sketch methods grow at the true height (two-view: the top of the true main branches, what the strokes
span).

- params (seed 004): TreeSketchNet reads the `tsn4` front view's `sketch_tsn`; species, levels and the parameter
  score (Weber-Penn trees only: the codec's dictionaries) beside the geometry.
- sketch-depth (seed 000): the `two-view` front view's `sketch_edges` and `trunk_strokes` through both pix2pix
  networks; with `silhouette_envelope` / `trunk_depth` stored, the networks' foreground depth errors too.
- two-view (seed 001): the `two-view:shared` front and side `sketch_strokes`.
- cloud (seed 003): a synthetic scan of the true mesh (`reconstruct.cloud_sampling`: leaf clutter, outliers, an
  occlusion wedge, seeded per tree) through `from_cloud`; also the scan's fit to the bark and the connectedness.
- photos (SfM): a leafless orbit rendered with Blender (Cycles), `from_photos` at the cameras' known poses.
"""
from __future__ import annotations

import dataclasses
import hashlib
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from renderers import Camera, ViewRenderer
from species.errors import TreefarmError
from species.skeleton import Skeleton
from species.tree_mesh import TreeMesh

__all__ = ["METHODS", "Method", "Needs", "HeldOutTree", "MethodResult", "EvalSettings", "MethodContext",
           "tree_rng_seed", "joined_share"]


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
    """How the evaluation measures: surface samples per mesh (0: no surface distances), the synthetic scan, and
    the photos' orbit (views 10 deg apart, leafless: digest and docs/reconstruct.md say why)."""

    surface_samples: int = 20_000
    cloud_points: int = 20_000
    cloud_leaf_fraction: float = 0.2
    cloud_outlier_fraction: float = 0.02
    cloud_wedge_deg: float = 30.0
    photo_views: int = 10
    photo_size: int = 400
    photo_samples: int = 4
    seed: int = 0


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

    def close(self) -> None:
        self.renderer.close()


@dataclass(frozen=True)
class Method:
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
    return float(result.fit.n_reached) / max(1, int(result.fit.n_used))


def _scorer(ctx: MethodContext, tree: HeldOutTree, cameras, seen_azimuths):
    from reconstruct.scoring import TreeScorer

    return TreeScorer(ctx.renderer, tree.skeleton, tree.mesh, cameras, seen_azimuths, ctx.settings.surface_samples)


def _pictures(ctx: MethodContext, tree: HeldOutTree, camera: Camera, skeleton: Skeleton,
              mesh: TreeMesh) -> list[tuple[str, np.ndarray]]:
    from reconstruct.scoring import depth_picture

    return [("reconstruction", depth_picture(ctx.renderer, mesh, skeleton, camera)),
            ("ground truth", depth_picture(ctx.renderer, tree.mesh, tree.skeleton, camera))]


def _view(tree: HeldOutTree, name: str) -> tuple[Camera, dict[str, np.ndarray]]:
    return tree.views[name]


# ------------------------------------------------------------------------------------------------ methods
def run_params(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    import reconstruct
    from reconstruct import metrics

    net = ctx.net("sketchnet")
    camera, images = _view(tree, "front")
    result = reconstruct.from_params(images["sketch_tsn"], net=net, height=tree.skeleton.height)
    start = time.perf_counter()
    row = _scorer(ctx, tree, [camera], (0,))(result.skeleton, result.mesh)
    if tree.species in net.codec.species:  # a species the network can name
        row["species_correct"] = float(result.params.get("species") == tree.species)
    if tree.params.get("generator", "weber_penn") == "weber_penn":
        row["levels_correct"] = float(int(result.params.get("levels", -1)) == int(tree.params.get("levels", -2)))
        row["param_score"] = metrics.parameter_scores(net.codec, result.params, tree.params)["score_overall"]
    timings = {**result.timings, "scoring": time.perf_counter() - start}
    cells = [("input", images["sketch_tsn"]), *_pictures(ctx, tree, camera, result.skeleton, result.mesh)]
    return MethodResult(row, timings, cells, {"sketchnet": net.source})


def run_sketch_depth(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    import reconstruct
    from reconstruct.scoring import network_depth_error

    silhouette_net, trunk_net = ctx.net("pix2pix-silhouette"), ctx.net("pix2pix-trunk")
    camera, images = _view(tree, "front")
    seed = tree_rng_seed(tree, "sketch-depth", ctx.settings.seed)
    result = reconstruct.from_sketch(images["sketch_edges"], images["trunk_strokes"], silhouette_net=silhouette_net,
                                     trunk_net=trunk_net, height=tree.skeleton.height,
                                     rng=np.random.default_rng(seed))
    start = time.perf_counter()
    row = _scorer(ctx, tree, [camera], (0,))(result.skeleton, result.mesh, result.maps["main_skeleton"])
    if "silhouette_envelope" in images:
        row["depth_error_silhouette"] = network_depth_error(silhouette_net, "silhouette", images)[0]
    if "trunk_depth" in images:
        row["depth_error_trunk"] = network_depth_error(trunk_net, "trunk", images)[0]
    timings = {**result.timings, "scoring": time.perf_counter() - start}
    cells = [("input", images["sketch_edges"]), ("trunk strokes", images["trunk_strokes"]),
             *_pictures(ctx, tree, camera, result.skeleton, result.mesh)]
    return MethodResult(row, timings, cells, {"pix2pix-silhouette": silhouette_net.source,
                                              "pix2pix-trunk": trunk_net.source})


def run_two_view(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    import reconstruct
    from reconstruct.scoring import main_branch_nodes

    (front_camera, front), (side_camera, side) = _view(tree, "front"), _view(tree, "side")
    seed = tree_rng_seed(tree, "two-view", ctx.settings.seed)
    start = time.perf_counter()
    result = reconstruct.two_view(front["sketch_strokes"], side["sketch_strokes"],
                                  height=float(main_branch_nodes(tree.skeleton)[:, 2].max()),
                                  rng=np.random.default_rng(seed), brush=False)
    timings = {**result.report["timings"], "total": time.perf_counter() - start}
    start = time.perf_counter()
    row = _scorer(ctx, tree, [front_camera, side_camera], (0, 90))(result.skeleton, result.mesh,
                                                                   result.report["main"].positions)
    timings["scoring"] = time.perf_counter() - start
    cells = [("input front", front["sketch_strokes"]), ("input side", side["sketch_strokes"]),
             *_pictures(ctx, tree, front_camera, result.skeleton, result.mesh)]
    return MethodResult(row, timings, cells)


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


def run_cloud(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    import reconstruct
    from reconstruct.cloud_sampling import WOOD, sample_tree_cloud
    from reconstruct.report import cloud_drawing

    s = ctx.settings
    seed = tree_rng_seed(tree, "cloud", s.seed)
    start = time.perf_counter()
    leaf = s.cloud_leaf_fraction if tree.mesh.leaves.n_faces else 0.0
    scan = sample_tree_cloud(tree.mesh, np.random.default_rng(seed), n_points=s.cloud_points, leaf_fraction=leaf,
                             outlier_fraction=s.cloud_outlier_fraction, occlusion_wedge_deg=s.cloud_wedge_deg)
    sampling = time.perf_counter() - start
    result = reconstruct.from_cloud(scan.points, seed=seed % 2**32)
    start = time.perf_counter()
    row = _cloud_scores(ctx, tree, result, scan.points[scan.labels == WOOD])
    timings = {"scan": sampling, **result.timings, "scoring": time.perf_counter() - start}
    cells = [("input scan", cloud_drawing(scan.points, 0)),
             *_pictures(ctx, tree, _front_camera(ctx, tree), *result.in_scan_frame())]
    return MethodResult(row, timings, cells)


def run_photos(tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    import reconstruct
    from PIL import Image

    from reconstruct.sfm import SfmSettings
    from renderers.blender import render_photos
    from renderers.camera import perspective_camera
    from species.tree_mesh import MeshPart

    s = ctx.settings
    seed = tree_rng_seed(tree, "photos", s.seed)
    leafless = dataclasses.replace(tree.mesh, leaves=MeshPart.empty())
    points = leafless.bark.vertices
    cameras = [perspective_camera(points, k * 10.0, 15.0 if k % 2 else 8.0, s.photo_size, name=f"view{k}")
               for k in range(s.photo_views)]
    with tempfile.TemporaryDirectory(prefix="treefarm-eval-photos-") as folder:
        start = time.perf_counter()
        photos = render_photos(leafless.to_glb(), cameras, Path(folder) / "photos", samples=s.photo_samples)
        rendering = time.perf_counter() - start
        with Image.open(photos.images[0]) as photo:
            first = np.asarray(photo.convert("RGB"))
        result = reconstruct.from_photos(Path(folder) / "photos", seed=seed % 2**31,
                                         settings=SfmSettings(poses="known", threads=1, seed=seed % 2**31),
                                         workdir=Path(folder) / "sfm")
    start = time.perf_counter()
    bare = dataclasses.replace(tree, mesh=leafless)
    in_world = result.base_points @ result.transform[:3, :3].T + result.transform[:3, 3]  # the renders' frame
    row = _cloud_scores(ctx, bare, result, in_world)
    timings = {"photos (Cycles)": rendering, **result.timings, "scoring": time.perf_counter() - start}
    cells = [("input photo", first), *_pictures(ctx, bare, _front_camera(ctx, bare), *result.in_scan_frame())]
    return MethodResult(row, timings, cells)


METHODS: dict[str, Method] = {
    "params": Method("params", Needs("tsn4", ("front",), ("sketch_tsn",)), run_params, ("sketchnet",),
                     "TreeSketchNet's dictionary from one sketch (seed 004)"),
    "sketch-depth": Method("sketch-depth", Needs("two-view", ("front",), ("sketch_edges", "trunk_strokes"),
                                                 ("silhouette_envelope", "trunk_depth")),
                           run_sketch_depth, ("pix2pix-silhouette", "pix2pix-trunk"),
                           "depth-guided growth from a sketch and trunk strokes (seed 000)"),
    "two-view": Method("two-view", Needs("two-view:shared", ("front", "side"), ("sketch_strokes",)), run_two_view,
                       (), "two orthogonal drawings, no network (seed 001)"),
    "cloud": Method("cloud", Needs(), run_cloud, (), "a synthetic scan through from_cloud (seed 003)"),
    "photos": Method("photos", Needs(), run_photos, (), "Blender photos through pycolmap SfM (slow)"),
}


def run_method(method: str, tree: HeldOutTree, ctx: MethodContext) -> MethodResult:
    """Run one method on one tree; TreefarmErrors (a tree the method cannot reconstruct) propagate."""
    if method not in METHODS:
        raise TreefarmError(f"unknown method {method!r}: allowed {', '.join(METHODS)}")
    return METHODS[method].run(tree, ctx)
