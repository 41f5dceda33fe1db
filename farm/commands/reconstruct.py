"""`farm reconstruct`: a tree from drawings, point clouds or photos, written as GLB (or OBJ for drawings).

  farm reconstruct SKETCH.png --out tree.glb                          parameters from one sketch (TreeSketchNet)
  farm reconstruct SKETCH.png --strokes STROKES.png --out tree.glb    depth-guided growth (seed 000)
  farm reconstruct --front FRONT.png --side SIDE.png --out tree.glb   two orthogonal drawings (seed 001)
  farm reconstruct CLOUD.xyz --out tree.glb [--skeleton-ply s.ply] [--qsm-csv q.csv]   a scan (AdTree, seed 003)
  farm reconstruct PHOTOS/ --method photos --out tree.glb [--height M]                 photos, SfM (seed 003)
  farm reconstruct A.laz B.laz SCANS/ --out TREES/                    a batch on Ray: one GLB each, summary.csv

--method is inferred from the inputs when omitted: one image -> params, an image with --strokes -> sketch-depth,
--front and --side -> two-view, cloud files -> cloud, a folder of images -> photos. A photo instead of a sketch (sketch-depth): --photo, its
blurred Canny edges become the silhouette sketch. --models: a model registry (its champions); by default the models
shipped in models/. --params-out writes the dictionary (params method), which `farm tree --params` rebuilds byte
for byte when both files share a stem. --report writes a PNG of the input, the maps, the skeleton and the result.
Drawings of any size are normalised as the training sketches were: black strokes on white, colour trunk strokes
in the palette of docs/reconstruct.md. The methods (the registry `reconstruct.methods.METHODS`):
"""
from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from reconstruct.fit_budget import DEFAULT_FIT_EVALS
from reconstruct.methods import INPUT_KINDS, METHODS, Method, RunOptions
from species.errors import user_path

from farm.commands import CommandLineError, reconstruct_cloud
from farm.commands.ray_options import check_workers
from farm.table import listed

# The RunOptions fields a drawing method may read that a flag of this command sets.
OPTION_FLAGS = {"photo": "--photo", "species": "--species"}


def _drawing_methods() -> list[Method]:
    return [m for m in METHODS.values() if m.reads[0].kind == "image"]


def register(subparsers) -> None:
    methods = "".join(f"  {m.name:<13} {m.summary} ({m.source})\n" for m in METHODS.values())
    parser = subparsers.add_parser("reconstruct", help="reconstruct a tree from sketches (GLB/OBJ)",
                                   description=__doc__ + methods, formatter_class=argparse.RawDescriptionHelpFormatter)
    positional: dict[str, list[str]] = {}  # kind -> the methods reading it as INPUT
    flags: dict[str, tuple] = {}           # input flag -> (its Input, the methods reading it)
    for method in METHODS.values():
        for item in method.reads:
            if item.flag:
                flags.setdefault(item.name, (item, []))[1].append(method.name)
            else:
                positional.setdefault(item.kind, []).append(method.name)
    parser.add_argument("inputs", nargs="*", metavar="INPUT",
                        help=", ".join(f"{INPUT_KINDS[kind][1]} ({', '.join(dict.fromkeys(names))})"
                                       for kind, names in positional.items()))
    parser.add_argument("--method", choices=list(METHODS), help="default: inferred from the inputs")
    for name, (item, names) in flags.items():
        parser.add_argument(f"--{name}", help=f"{item.help or item.what} ({', '.join(names)})")
    parser.add_argument("--photo", action="store_true",
                        help="INPUT is a photo: its blurred Canny edges are the silhouette sketch (sketch-depth)")
    parser.add_argument("--species", default=None,
                        help="sketch-depth: a colonization preset (sc_*), or auto (TreeSketchNet reads it); "
                             "default sc_round_maple")
    parser.add_argument("--height", type=float, help="tree height in metres (default: the method's)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the growth draws (default 0)")
    parser.add_argument("--fit-evals", type=int, default=None, metavar="N",
                        help="candidate trees the fit to the drawing grows and redraws (default "
                             f"{DEFAULT_FIT_EVALS}, a few seconds; 0: the method's first guess as it is)")
    parser.add_argument("--models", help="model registry URI or folder (default: the shipped models/)")
    parser.add_argument("--params-out", help="write the parameter dictionary here (params method)")
    parser.add_argument("--format", choices=("glb", "obj"), default=None, help="default: from --out's suffix")
    parser.add_argument("--report", help="write a PNG: input, maps, skeleton and result side by side")
    parser.add_argument("--verbose", action="store_true", help="print each stage's seconds")
    parser.add_argument("--out", required=True,
                        help="the tree file (FILE.glb, or FILE.obj with its MTL), or a folder for a batch")
    reconstruct_cloud.add_arguments(parser)
    parser.set_defaults(run=run)


def _input_flags(method: Method) -> list[str]:
    return [f"--{item.name}" for item in method.reads if item.flag]


def _given(args: argparse.Namespace, method: Method, switches_only: bool = False) -> list[str]:
    """The method's flags on the command line: its input flags given, and its options set (only the switches,
    such as --photo, with `switches_only`)."""
    given = [f"--{item.name}" for item in method.reads if item.flag and getattr(args, item.name) is not None]
    for option in method.options:
        value = getattr(args, option, None) if option in OPTION_FLAGS else None
        if value is True or (not switches_only and value not in (None, False)):
            given.append(OPTION_FLAGS[option])
    return given


def _inferred(args: argparse.Namespace) -> str:
    """The drawing method the flags given point to: the one that reads most of them (input flags and switches),
    more input flags breaking a tie; with none given, the first that reads one INPUT and nothing else."""
    drawing = _drawing_methods()
    best = max(drawing, key=lambda m: (len(_given(args, m, switches_only=True)), len(_input_flags(m))))
    if _given(args, best, switches_only=True):
        return best.name
    return next((m.name for m in drawing if len(m.reads) == 1 and not m.reads[0].flag), drawing[0].name)


def _method(args: argparse.Namespace) -> Method:
    method = METHODS[args.method or _inferred(args)]
    kind = method.reads[0].kind
    if kind != "image":
        raise CommandLineError(f"--method {method.name} takes {INPUT_KINDS[kind][1]} as INPUT (got none that exist)")
    cloud_only = [flag for flag, value in (("--skeleton-ply", args.skeleton_ply), ("--qsm-csv", args.qsm_csv),
                                           ("--branches-csv", args.branches_csv), ("--workers", args.workers),
                                           ("--address", args.address)) if value]
    if cloud_only or args.up != "z" or args.frame != "base":
        scans = [m.name for m in METHODS.values() if m.reads[0].kind != "image"]
        raise CommandLineError(f"{', '.join(cloud_only) or '--up/--frame'} are {listed(scans)} options, not "
                               f"{method.name}'s")
    flagged = [item for item in method.reads if item.flag]
    n_inputs = len(method.reads) - len(flagged)
    if not n_inputs:
        if any(getattr(args, item.name) is None for item in flagged) or args.inputs:
            raise CommandLineError(f"--method {method.name} takes "
                                   f"{' and '.join(f'--{i.name} {i.name.upper()}.png' for i in flagged)} (no INPUT)")
    else:
        flag_only = [m for m in _drawing_methods() if m is not method and all(item.flag for item in m.reads)]
        if len(args.inputs) != n_inputs or any(_given(args, m) for m in flag_only):
            count = "one INPUT image" if n_inputs == 1 else f"{n_inputs} INPUT images"
            elsewhere = "".join(f"; {'/'.join(_input_flags(m))} are for {m.name}" for m in flag_only)
            raise CommandLineError(f"--method {method.name} takes {count} (got {len(args.inputs)}){elsewhere}")
        missing = [item for item in flagged if getattr(args, item.name) is None]
        if missing:
            item = missing[0]
            raise CommandLineError(f"--method {method.name} needs --{item.name} {item.name.upper()}.png "
                                   f"({item.what})")
    own = set(_given(args, method))
    for other in _drawing_methods():
        if other is not method and set(_given(args, other)) - own:
            options = [OPTION_FLAGS[o] for o in other.options if o in OPTION_FLAGS]
            raise CommandLineError(f"{listed(_input_flags(other) + options)} are {other.name} options, not "
                                   f"{method.name}'s")
    if args.fit_evals is not None and "fit_evals" not in method.options:
        fitting = [m.name for m in METHODS.values() if "fit_evals" in m.options]
        raise CommandLineError(f"--fit-evals is an option of {listed(fitting)}, not {method.name}'s")
    if not method.rebuilds and args.params_out:
        rebuilding = [m.name for m in METHODS.values() if m.rebuilds]
        raise CommandLineError(f"--params-out writes the {listed(rebuilding)} method's dictionary; --method "
                               f"{method.name} has none")
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
    return open_registry(args.models, create=False)


def run(args: argparse.Namespace) -> int:
    check_workers(args.workers)
    clouds = reconstruct_cloud.cloud_inputs(args)
    if clouds is not None:
        if args.fit_evals is not None:
            raise CommandLineError("--fit-evals fits a drawing method's tree to its drawing; a point cloud's tree "
                                   "is measured from its points")
        if args.height is not None and not (np.isfinite(args.height) and args.height > 0):
            raise CommandLineError(f"--height {args.height} is invalid: allowed a number of metres > 0")
        if args.seed < 0:
            raise CommandLineError(f"--seed {args.seed} is invalid: allowed an integer >= 0")
        return reconstruct_cloud.run(args, *clouds)
    method = _method(args)
    out, fmt = _output(args)
    if args.seed < 0:
        raise CommandLineError(f"--seed {args.seed} is invalid: allowed an integer >= 0")
    if args.fit_evals is not None and args.fit_evals < 0:
        raise CommandLineError(f"--fit-evals {args.fit_evals} is invalid: allowed an integer >= 0 (0 turns "
                               "fitting off)")
    # Here, after the arguments are checked: the dataset format's readers and the meshing (start-up time).
    from farm.dataset import read_image
    from species.meshing import write_tree

    started = time.perf_counter()
    models = _models(args)
    positional = iter(args.inputs)
    inputs = {item.name: read_image(getattr(args, item.name) if item.flag else next(positional))
              for item in method.reads}
    fit_evals = DEFAULT_FIT_EVALS if args.fit_evals is None else args.fit_evals
    result = method.run(inputs, RunOptions(seed=args.seed, height=args.height, models=models, species=args.species,
                                           photo=args.photo, fit_evals=fit_evals))
    shown = {**inputs, **result.maps}  # a panel names a map of the result, or else an input
    panels = [(label, shown[name]) for label, name in method.report_panels]
    fit = result.maps.get("fit")  # a reconstruct.fitting.FitRecord where the method fitted its tree
    if fit is not None:
        panels += fit.panels()
    mesh = replace(result.mesh, name=out.stem)
    if args.params_out:
        with user_path(args.params_out, "write"):
            Path(args.params_out).parent.mkdir(parents=True, exist_ok=True)
            Path(args.params_out).write_text(json.dumps(result.params, indent=1, sort_keys=True) + "\n")
    files = write_tree(mesh, out, fmt)
    read = result.maps.get("species")  # (name, confidence) where the method reads the species
    species_read = f"species {read[0]} (confidence {read[1]:.2f})" if read else ""
    if args.report:
        from reconstruct.report import write_report

        with user_path(args.report, "write"):
            write_report(args.report, panels, result.skeleton, mesh,
                         title=f"{method.name}: {Path(out).name}" + (f", {species_read}" if read else ""))
    if args.verbose:
        reconstruct_cloud.print_stages(result.timings)
        if fit is not None:
            print("  fit: outline IoU after N evaluations: " + _by_evaluations(fit.trace.best))
            if fit.species_scores:
                print("  fit: species tried (outline IoU, network's probability): " + ", ".join(
                    f"{name} {score:.2f} ({probability:.2f})" for name, (score, probability) in fit.species_scores.items()))
    skeleton = result.skeleton
    fitted = f"outline IoU {fit.first_score:.2f} -> {fit.score:.2f}, " if fit is not None else ""
    print(f"{method.name}: {species_read + ', ' if read else ''}{fitted}{skeleton.n_nodes} nodes, height "
          f"{skeleton.height:.2f} m, crown {skeleton.crown_radius:.2f} m, {mesh.n_faces} faces -> {files[0]} "
          f"({time.perf_counter() - started:.2f} s)")
    return 0


def _by_evaluations(best: list[float]) -> str:
    """The best score after 1, 2, 4, ... evaluations and after the last: what a larger or smaller budget buys."""
    marks = sorted({min(2**k, len(best)) for k in range(len(best).bit_length() + 1)})
    return ", ".join(f"{n}: {best[n - 1]:.2f}" for n in marks)
