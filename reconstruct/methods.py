"""The reconstruction methods, one registry: an entry per method (its name, what it reads, which trained models it
needs, and `run`), and the options every `run` takes.

`farm reconstruct` (its --method choices, its input flags, what each method is told), `farm evaluate` (which dataset
views feed a method, which networks it loads), benchmarks/bench_reconstruct.py and the methods table of
docs/reconstruct.md (`methods_table`) read METHODS, so a new method is one entry here: `Input`s naming what it reads
and a `run(inputs, options)` that returns a `reconstruct.Reconstruction` (tests/reconstruct/test_methods.py
registers a throwaway one and follows it to every place).

Each `run` imports its method's module when called: the methods pull in scipy, OpenCV, torch and pycolmap, and the
command line reads this registry at start-up.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Mapping

import numpy as np

from species.errors import TreefarmError

from .fit_budget import DEFAULT_FIT_EVALS
from .photo_folder import CAMERA_HEIGHT_M

if TYPE_CHECKING:  # the result's module imports scipy (see the module docstring)
    from .result import Reconstruction

__all__ = ["METHODS", "Method", "Input", "Rendered", "RunOptions", "MethodError", "INPUT_KINDS", "get_method",
           "methods_table", "DEFAULT_FIT_EVALS"]

# What a method can read, by kind: (one, several) as messages name them.
INPUT_KINDS = {"image": ("an image file", "image files"), "cloud": ("a point cloud", "cloud files"),
               "photos": ("a folder of photos", "photo folders")}


class MethodError(TreefarmError):
    """A reconstruction method that is not in the registry."""


@dataclass(frozen=True)
class Rendered:
    """Where a generated dataset holds an input: output `output` of view `view` of rig `rig` (`renderers`)."""

    rig: str
    view: str
    output: str


@dataclass(frozen=True)
class Input:
    """One thing a method reads.

    name     : its key in `run`'s inputs; on the command line `--NAME NAME.png` when `flag`, else the INPUT.
    kind     : an INPUT_KINDS key: "image" (an array, as `farm.dataset.read_image` reads a file), "cloud" (a point
               cloud file or an (N, 3) array), "photos" (a folder of photos).
    what     : what it is, in a few words, for messages and the docs.
    help     : the command line's help for its flag (default `what`).
    flag     : given as `--NAME` rather than as the positional INPUT.
    rendered : the renderers' output that stands for it in a generated dataset; None where the evaluation makes the
               input from the true tree itself (a scan, photos).
    """

    name: str
    kind: str
    what: str
    help: str = ""
    flag: bool = False
    rendered: Rendered | None = None


@dataclass(frozen=True)
class RunOptions:
    """What a method's `run` is told besides its inputs; each method reads the fields it needs.

    seed       : its draws: the dictionary's seed (params), growth (sketch-depth, two-view: a numpy Generator seeded
                 with it), the completion and SfM (cloud, photos).
    height     : the tree's height in metres; None for the method's own (a drawing has no scale).
    models     : a model registry (its champions) or None for the shipped models; nets : predictors already loaded,
                 by trainers task name, used before `models`.
    species    : sketch-depth's colonization preset, "auto" (TreeSketchNet reads it) or None (its default); the
                 photos' hull growth's preset (None: the same default).
    shape      : photos: "sparse" (the crown from the SfM points) or "hull" (grown in the photos' visual hull).
    masks      : photos: the hull's tree masks, "network" (the "tree-mask" model: nets, else models) or "classical".
    photo      : sketch-depth reads a photo: its blurred edges are the sketch.
    brush      : two-view's stroke kind; None tells it from the drawings.
    up, frame, completion : cloud and photos (`reconstruct.from_cloud`); poses, threads : photos' SfM
                 (`reconstruct.sfm.SfmSettings`); workdir : photos: where COLMAP's files are kept (None: a
                 temporary folder); log : photos: the file COLMAP's log goes to (None: the terminal);
                 progress : photos: told each stage's progress (`reconstruct.sfm.Progress`).
    name       : the mesh's name (cloud, photos).
    fit_evals  : the drawing methods' fit to their input (`reconstruct.fitting`): candidate trees grown and redrawn;
                 0 keeps the method's first guess; renderer : the `renderers.ViewRenderer` the fit redraws them with
                 (None: the method makes one, a GL context per call).
    """

    seed: int = 0
    height: float | None = None
    models: Any = None
    nets: Mapping[str, Any] = field(default_factory=dict)
    species: str | None = None
    photo: bool = False
    brush: bool | None = None
    up: str = "z"
    frame: str = "base"
    completion: bool = True
    poses: str = "auto"
    threads: int = 0
    name: str = "tree"
    workdir: Any = None
    log: Any = None
    progress: Callable[[str, int, int], None] | None = None
    fit_evals: int = DEFAULT_FIT_EVALS
    renderer: Any = None
    shape: str = "hull"
    masks: str = "network"
    camera_height: float = CAMERA_HEIGHT_M


@dataclass(frozen=True)
class Method:
    """One reconstruction method.

    name     : its name everywhere (`farm reconstruct --method`, `farm evaluate --methods`, report rows).
    reads    : its inputs, in the order the command line reads them.
    run      : run(inputs, options) -> Reconstruction, with `inputs` by `Input.name` and `options` a RunOptions.
    models   : the trained networks it loads (trainers task names).
    options  : the RunOptions fields it reads besides seed, height, models and nets.
    summary  : how it works, in one line; source : the paper or seed document it follows.
    panels   : the --report panels: (label, name of a map of its result, or else of one of its inputs); empty: its
               inputs.
    rebuilds : its dictionary rebuilds the tree (`farm tree --params`), so the command line writes it (--params-out).
    """

    name: str
    reads: tuple[Input, ...]
    run: Callable[[Mapping[str, Any], RunOptions], Reconstruction]
    models: tuple[str, ...] = ()
    options: tuple[str, ...] = ()
    summary: str = ""
    source: str = ""
    panels: tuple[tuple[str, str], ...] = ()
    rebuilds: bool = False

    @property
    def report_panels(self) -> tuple[tuple[str, str], ...]:
        return self.panels or tuple((item.name, item.name) for item in self.reads)


# ------------------------------------------------------------------------------------------------ the methods
def _run_params(inputs, options: RunOptions):
    from .from_params import from_params  # imported when run (module docstring)

    return from_params(inputs["sketch"], models=options.models, net=options.nets.get("sketchnet"), seed=options.seed,
                       height=options.height, fit_evals=options.fit_evals, renderer=options.renderer)


def _run_sketch_depth(inputs, options: RunOptions):
    from .from_sketch import from_sketch  # imported when run (module docstring)

    nets = options.nets
    return from_sketch(inputs["sketch"], inputs["strokes"], models=options.models, species=options.species,
                       height=options.height, rng=np.random.default_rng(options.seed), photo=options.photo,
                       silhouette_net=nets.get("pix2pix-silhouette"), trunk_net=nets.get("pix2pix-trunk"),
                       sketchnet=nets.get("sketchnet"), fit_evals=options.fit_evals, renderer=options.renderer)


def _run_two_view(inputs, options: RunOptions):
    from .two_view import two_view  # imported when run (module docstring)

    return two_view(inputs["front"], inputs["side"], height=options.height, rng=np.random.default_rng(options.seed),
                    brush=options.brush, fit_evals=options.fit_evals)


def _run_cloud(inputs, options: RunOptions):
    from .from_cloud import from_cloud  # imported when run (module docstring)

    return from_cloud(inputs["cloud"], up=options.up, frame=options.frame, completion=options.completion,
                      seed=options.seed, name=options.name)


def _run_photos(inputs, options: RunOptions):
    from .from_photos import from_photos  # imported when run (module docstring): pycolmap
    from .sfm import SfmSettings

    settings = SfmSettings(poses=options.poses, threads=options.threads, seed=options.seed)
    return from_photos(inputs["photos"], height=options.height, frame=options.frame, completion=options.completion,
                       seed=options.seed, settings=settings, name=options.name, workdir=options.workdir,
                       log=options.log, progress=options.progress, shape=options.shape,
                       species=options.species, masks=options.masks, models=options.models,
                       mask_net=options.nets.get("tree-mask"), camera_height=options.camera_height)


METHODS: dict[str, Method] = {
    "params": Method(
        "params", (Input("sketch", "image", "a sketch, black strokes on white",
                         rendered=Rendered("tsn4", "front", "sketch_tsn")),),
        _run_params, models=("sketchnet",), options=("fit_evals",), panels=(("input", "input"),), rebuilds=True,
        summary="TreeSketchNet predicts a Sapling dictionary; the Weber-Penn generator grows it",
        source="seed 004"),
    "sketch-depth": Method(
        "sketch-depth", (Input("sketch", "image", "the tree's outline sketch (or a photo, with --photo)",
                               rendered=Rendered("two-view", "front", "sketch_edges")),
                         Input("strokes", "image", "the colour trunk strokes",
                               help="colour trunk strokes drawn over the sketch", flag=True,
                               rendered=Rendered("two-view", "front", "trunk_strokes"))),
        _run_sketch_depth, models=("pix2pix-silhouette", "pix2pix-trunk"), options=("photo", "species", "fit_evals"),
        panels=(("input", "sketch"), ("front depth", "front"), ("trunk depth", "trunk_depth"),
                ("strokes", "strokes")),
        summary="the silhouette and trunk pix2pix networks predict depth; a colonization tree grows inside the "
                "crown from the traced branches",
        source="seed 000 ch. 3"),
    "two-view": Method(
        "two-view", (Input("front", "image", "the front drawing", flag=True,
                           rendered=Rendered("two-view:shared", "front", "sketch_strokes")),
                     Input("side", "image", "the side drawing", help="the side drawing, 90 degrees from the front",
                           flag=True, rendered=Rendered("two-view:shared", "side", "sketch_strokes"))),
        _run_two_view, options=("brush", "fit_evals"),
        summary="no network: 2D skeletons, the front lifted on the side strokes, twigs clipped by both outlines",
        source="seed 001"),
    "cloud": Method(
        "cloud", (Input("cloud", "cloud", "a point cloud (.xyz, .txt, .csv, .pts, .ply, .las, .laz)"),),
        _run_cloud, options=("up", "frame", "completion"),
        summary="AdTree's skeleton and QSM measures, then seed 003's completion (twigs, leaves, grafts)",
        source="AdTree, seed 003"),
    "photos": Method(
        "photos", (Input("photos", "photos", "a folder of photos (with cameras.json when the poses are known)"),),
        _run_photos, models=("tree-mask",), options=("frame", "completion", "poses", "shape", "species", "masks",
                                                             "camera_height"),
        summary="pycolmap SfM points, levelled, scaled and isolated from the ground, then the cloud method",
        source="SfM, seed 003"),
}


def get_method(name: str) -> Method:
    """The registry's method called `name`; MethodError naming the known ones otherwise."""
    if name not in METHODS:
        raise MethodError(f"unknown method {name!r}: allowed {', '.join(METHODS)}")
    return METHODS[name]


def methods_table() -> str:
    """The registry as the Markdown table of docs/reconstruct.md."""
    rows = ["| method | what it reads | trained models | how | source |", "|---|---|---|---|---|"]
    for method in METHODS.values():
        reads = " + ".join(f"`--{item.name}` {item.what}" if item.flag else item.what for item in method.reads)
        models = ", ".join(method.models) or "none"
        rows.append(f"| `{method.name}` | {reads} | {models} | {method.summary} | {method.source} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(methods_table(), end="")
