"""`farm reconstruct`: a tree from drawings, point clouds or photos, written as GLB (or OBJ for drawings).

  farm reconstruct SKETCH.png --out tree.glb                          parameters from one sketch (TreeSketchNet)
  farm reconstruct SKETCH.png --strokes STROKES.png --out tree.glb    depth-guided growth (seed 000)
  farm reconstruct --front FRONT.png --side SIDE.png --out tree.glb   two orthogonal drawings (seed 001)
  farm reconstruct CLOUD.xyz --out tree.glb [--skeleton-ply s.ply] [--qsm-csv b.csv]   a scan (AdTree, seed 003)
  farm reconstruct PHOTOS/ --method photos --out tree.glb [--height M]                 photos, SfM (seed 003)
  farm reconstruct A.laz B.laz SCANS/ --out TREES/                    a batch on Ray: one GLB each, summary.csv

--method is inferred from the inputs when omitted: one image -> params, an image with --strokes -> sketch-depth,
--front and --side -> two-view, cloud files -> cloud, a folder of images -> photos. A photo instead of a sketch (sketch-depth): --photo, its
blurred Canny edges become the silhouette sketch. --models: a model registry (its champions); by default the models
shipped in models/. --params-out writes the dictionary (params method), which `farm tree --params` rebuilds byte
for byte when both files share a stem. --report writes a PNG of the input, the maps, the skeleton and the result.
Drawings of any size are normalised as the training sketches were: black strokes on white, colour trunk strokes
in the palette of docs/reconstruct.md.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from species.errors import user_path

from farm.commands import CommandLineError, reconstruct_cloud

METHODS = ("params", "sketch-depth", "two-view", "cloud", "photos")


def register(subparsers) -> None:
    parser = subparsers.add_parser("reconstruct", help="reconstruct a tree from sketches (GLB/OBJ)",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("inputs", nargs="*", metavar="INPUT",
                        help="the sketch (params, sketch-depth), cloud files or photo folders (cloud, photos)")
    parser.add_argument("--method", choices=METHODS, help="default: inferred from the inputs")
    parser.add_argument("--strokes", help="colour trunk strokes drawn over the sketch (sketch-depth)")
    parser.add_argument("--photo", action="store_true",
                        help="INPUT is a photo: its blurred Canny edges are the silhouette sketch (sketch-depth)")
    parser.add_argument("--front", help="the front drawing (two-view)")
    parser.add_argument("--side", help="the side drawing, 90 degrees from the front (two-view)")
    parser.add_argument("--species", default=None,
                        help="sketch-depth: a colonization preset (sc_*), or auto (TreeSketchNet reads it); "
                             "default sc_round_maple")
    parser.add_argument("--height", type=float, help="tree height in metres (default: the method's)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the growth draws (default 0)")
    parser.add_argument("--models", help="model registry URI or folder (default: the shipped models/)")
    parser.add_argument("--params-out", help="write the parameter dictionary here (params method)")
    parser.add_argument("--format", choices=("glb", "obj"), default=None, help="default: from --out's suffix")
    parser.add_argument("--report", help="write a PNG: input, maps, skeleton and result side by side")
    parser.add_argument("--out", required=True,
                        help="the tree file (FILE.glb, or FILE.obj with its MTL), or a folder for a batch")
    reconstruct_cloud.add_arguments(parser)
    parser.set_defaults(run=run)


def _method(args: argparse.Namespace) -> str:
    two_view = args.front is not None or args.side is not None
    method = args.method or ("two-view" if two_view else "sketch-depth" if args.strokes or args.photo else "params")
    if method in ("cloud", "photos"):
        raise CommandLineError(f"--method {method} takes {'cloud files' if method == 'cloud' else 'photo folders'} "
                               "as INPUT (got none that exist)")
    cloud_only = [flag for flag, value in (("--skeleton-ply", args.skeleton_ply), ("--qsm-csv", args.qsm_csv),
                                           ("--workers", args.workers), ("--address", args.address)) if value]
    if cloud_only or args.up != "z" or args.frame != "base":
        raise CommandLineError(f"{', '.join(cloud_only) or '--up/--frame'} are cloud and photos options, not "
                               f"{method}'s")
    if method == "two-view":
        if args.front is None or args.side is None or args.inputs:
            raise CommandLineError("--method two-view takes --front FRONT.png and --side SIDE.png (no INPUT)")
    elif len(args.inputs) != 1 or two_view:
        raise CommandLineError(f"--method {method} takes one INPUT image (got {len(args.inputs)}); --front/--side "
                               "are for two-view")
    if method == "sketch-depth" and args.strokes is None:
        raise CommandLineError("--method sketch-depth needs --strokes STROKES.png (the colour trunk strokes)")
    if method != "sketch-depth" and (args.strokes or args.photo or args.species):
        raise CommandLineError(f"--strokes, --photo and --species are sketch-depth options, not {method}'s")
    if method != "params" and args.params_out:
        raise CommandLineError(f"--params-out writes the params method's dictionary; --method {method} has none")
    return method


def _output(args: argparse.Namespace) -> tuple[Path, str]:
    out = Path(args.out)
    suffix = out.suffix.lower().lstrip(".")
    fmt = args.format or (suffix if suffix in ("glb", "obj") else "")
    if fmt not in ("glb", "obj") or suffix != fmt:
        raise CommandLineError(f"--out {args.out} must name a .glb or .obj file matching --format "
                               f"(got suffix {out.suffix!r}{', --format ' + args.format if args.format else ''})")
    if args.height is not None and not (np.isfinite(args.height) and args.height > 0):
        raise CommandLineError(f"--height {args.height} is invalid: allowed a number of metres > 0")
    return out, fmt


def _models(args):
    if args.models is None:
        return None
    from trainers.registry import check_registry_exists, open_registry

    check_registry_exists(args.models)
    return open_registry(args.models)


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    import reconstruct
    from farm.commands.tree import write_tree
    from farm.dataset import read_image

    clouds = reconstruct_cloud.cloud_inputs(args)
    if clouds is not None:
        if args.height is not None and not (np.isfinite(args.height) and args.height > 0):
            raise CommandLineError(f"--height {args.height} is invalid: allowed a number of metres > 0")
        if args.seed < 0:
            raise CommandLineError(f"--seed {args.seed} is invalid: allowed an integer >= 0")
        return reconstruct_cloud.run(args, *clouds)
    method = _method(args)
    out, fmt = _output(args)
    if args.seed < 0:
        raise CommandLineError(f"--seed {args.seed} is invalid: allowed an integer >= 0")
    started = time.perf_counter()
    models = _models(args)
    rng = np.random.default_rng(args.seed)
    if method == "params":
        image = read_image(args.inputs[0])
        result = reconstruct.from_params(image, models=models, seed=args.seed, height=args.height)
        panels = [("input", result.maps["input"])]
    elif method == "sketch-depth":
        image = read_image(args.inputs[0])
        strokes = read_image(args.strokes)
        result = reconstruct.from_sketch(image, strokes, models=models, species=args.species, height=args.height,
                                         rng=rng, photo=args.photo)
        panels = [("input", result.maps["sketch"]), ("front depth", result.maps["front"]),
                  ("trunk depth", result.maps["trunk_depth"]), ("strokes", result.maps["strokes"])]
    else:
        front, side = read_image(args.front), read_image(args.side)
        result = reconstruct.two_view(front, side, height=args.height, rng=rng)
        panels = [("front", front), ("side", side)]
    mesh = replace(result.mesh, name=out.stem)
    if args.params_out:
        with user_path(args.params_out, "write"):
            Path(args.params_out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.params_out).write_text(json.dumps(result.params, indent=1, sort_keys=True) + "\n")
    files = write_tree(mesh, out, fmt)
    if args.report:
        from reconstruct.report import write_report

        with user_path(args.report, "write"):
            write_report(args.report, panels, result.skeleton, mesh, title=f"{method}: {Path(out).name}")
    skeleton = result.skeleton
    stages = ", ".join(f"{k} {v:.2f}" for k, v in result.timings.items() if k != "total")
    print(f"{method}: {skeleton.n_nodes} nodes, height {skeleton.height:.2f} m, crown {skeleton.crown_radius:.2f} m, "
          f"{mesh.n_faces} faces -> {files[0]} ({time.perf_counter() - started:.2f} s; {stages})")
    return 0
