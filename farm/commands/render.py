"""`farm render`: grow one tree and write its views (maps and sketch styles) as PNGs with a cameras.json,
plus a contact_sheet.png of views x outputs to look at.

  farm render --species NAME --seed N [--params DICT.json] --rig tsn4|orbit:N|two-view[:shared][:jitter]
              --styles depth,mask,sketch_tsn,... --size PX [--backend pyrender|blender] --out DIR
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import species
from species.errors import user_path

from farm.commands import CommandLineError, check_flag_int
from farm.commands.tree import load_params
from farm.table import counted

# What a command runs is imported inside its functions: `farm --help` loads every command module (start-up time).

BACKENDS = ("pyrender", "blender")
# Float maps in [0, 1] are written as 16-bit PNGs: value = round(x * 65535).
UNIT_SCALE = 1.0 / 65535.0
# The largest image side, as a job spec's render.size allows: beyond it the GL context refuses the framebuffer.
MAX_SIZE = 4096


def register(subparsers) -> None:
    parser = subparsers.add_parser("render", help="render one tree's views, maps and sketches as PNGs",
                                   description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--species", help="preset name (see `farm species`); needed unless --params is given")
    parser.add_argument("--seed", type=int, default=0, help="seed for sampling the preset and the views (default 0)")
    parser.add_argument("--params", metavar="DICT.json", help="a parameter dictionary to grow instead of sampling")
    parser.add_argument("--rig", default="tsn4", help="tsn4, orbit:N[:E1,E2], two-view[:shared], optionally :jitter")
    parser.add_argument("--styles", default=None,
                        help="comma-separated outputs (maps and sketch styles); default the farm's default set")
    parser.add_argument("--size", type=int, default=256, help="image size in pixels (default 256)")
    parser.add_argument("--backend", choices=BACKENDS, default="pyrender",
                        help="pyrender (maps and sketches) or blender (Cycles photos)")
    parser.add_argument("--samples", type=int, default=16, help="Cycles samples per pixel (blender backend)")
    parser.add_argument("--out", required=True, help="output folder")
    parser.set_defaults(run=run)


def _tree_params(args: argparse.Namespace) -> dict:
    if args.params:
        return load_params(args.params)
    if not args.species:
        raise CommandLineError("give --species NAME (see `farm species`) or --params DICT.json")
    return species.sample(args.species, np.random.default_rng(args.seed))


def encode_image(name: str, image: np.ndarray, camera) -> tuple[np.ndarray, dict]:
    """An output array as a PNG-ready array and its decoding note: metric depth becomes uint16 with a metres
    scale (0 = background), [0, 1] floats become uint16 / 65535, masks and ids stay uint8 values."""
    from renderers import LABEL_MAPS, METRIC_MAPS

    if name in METRIC_MAPS:
        scale = max(float(camera.far), 1e-6) / 65535.0
        return np.round(image / scale).astype(np.uint16), {"scale": scale, "unit": "metres", "background": 0}
    if image.dtype == np.float32 or image.dtype == np.float64:
        return np.round(np.clip(image, 0.0, 1.0) * 65535).astype(np.uint16), {"scale": UNIT_SCALE, "unit": "1"}
    return image, {"scale": 1, "unit": "label" if name in LABEL_MAPS else "8-bit"}


def _write_png(path: Path, image: np.ndarray) -> None:
    """One view's output as a PNG file, by the dataset's map codec (8- or 16-bit, RGB or grey)."""
    from farm.dataset.image_codec import encode_pixels

    with user_path(path, "write"):
        path.write_bytes(encode_pixels(image))


def _render_pyrender(args, mesh, skeleton, outputs, out: Path) -> list[dict]:
    from renderers import ViewRenderer, views_sheet_rows, write_contact_sheet

    renderer = ViewRenderer(args.size)
    start = time.perf_counter()
    views = renderer.render(mesh, skeleton, args.rig, outputs, np.random.default_rng(args.seed))
    per_view = (time.perf_counter() - start) / len(views)
    records = []
    for view in views:
        files = {}
        for name, image in view.images.items():
            data, note = encode_image(name, image, view.camera)
            filename = f"view{view.index:02d}_{view.name}_{name}.png"
            _write_png(out / filename, data)
            files[name] = {"file": filename, **note}
        records.append({"index": view.index, **view.camera.to_dict(), "images": files})
        print(f"view {view.index} {view.name:>12}: {per_view * 1000:.0f} ms "
              f"(pyrender, {counted(len(outputs), 'output')})")
    renderer.close()
    with user_path(out / "contact_sheet.png", "write"):
        write_contact_sheet(out / "contact_sheet.png", views_sheet_rows(views), cell=min(args.size, 256))
    return records


def _render_blender(args, mesh, out: Path) -> list[dict]:
    try:
        from renderers import blender
    except ImportError as exc:
        raise CommandLineError(f"--backend blender is unavailable ({exc}): run `make env` to build .venv-blender, "
                               f"or use --backend pyrender") from None
    if not hasattr(blender, "render_photos"):
        raise CommandLineError("--backend blender is not installed in this tree (renderers.blender has no "
                               "render_photos()): use --backend pyrender")
    from renderers import make_rig, write_contact_sheet

    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    cameras = make_rig(args.rig, points, args.size, np.random.default_rng(args.seed))
    photos = blender.render_photos(mesh.to_glb(), cameras, out, samples=args.samples)
    for camera, seconds in zip(cameras, photos.render_seconds):
        print(f"view {camera.name:>12}: {seconds * 1000:.0f} ms (blender cycles, {args.samples} samples)")
    with user_path(out / "contact_sheet.png", "write"):
        write_contact_sheet(out / "contact_sheet.png", _photo_sheet_rows(photos), cell=min(args.size, 256))
    return json.loads(photos.cameras_json.read_text())["views"]


def _photo_sheet_rows(photos) -> list:
    """Contact sheet rows of a Blender photos job: one row per camera, its photo, depth and part mask."""
    from renderers import viewable

    from farm.dataset.image_codec import decode_map

    rows = []
    for camera, photo, depth, mask, scale in zip(photos.cameras, photos.images, photos.depths, photos.masks,
                                                 photos.depth_scales):
        rgb = decode_map(photo.read_bytes())[..., :3]
        metres = decode_map(depth.read_bytes(), scale=scale, offset=0.0)  # 16-bit, `scale` metres per unit
        labels = decode_map(mask.read_bytes())
        rows.append((camera.name, [("photo", rgb), ("depth", viewable("depth", metres)),
                                   ("mask", viewable("mask", labels))]))
    return rows


def check_out_folder(out: Path) -> None:
    """Refuse `--out` before anything is grown: it must be a folder, or a path where one can be made."""
    existing = out
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        where = "" if existing == out else f" ({existing} is a file)"
        raise CommandLineError(f"--out {out} is not a folder{where}: allowed a folder, made if missing")
    if not os.access(existing, os.W_OK):
        raise CommandLineError(f"--out {out}: cannot write {existing} (permission denied): allowed a folder you "
                               f"can write")


def run(args: argparse.Namespace) -> int:
    from renderers import DEFAULT_OUTPUTS, check_outputs, rig_parts

    outputs = check_outputs(DEFAULT_OUTPUTS if args.styles is None
                            else [s.strip() for s in args.styles.split(",") if s.strip()])
    rig_parts(args.rig)
    check_flag_int("--size", args.size, 8, MAX_SIZE)
    check_flag_int("--seed", args.seed, 0)
    check_flag_int("--samples", args.samples, 1)
    params = _tree_params(args)
    out = Path(args.out)
    check_out_folder(out)
    start = time.perf_counter()
    skeleton, mesh = species.rebuild(params)
    print(f"tree: {len(skeleton)} nodes, {mesh.n_faces} triangles, grown and meshed in "
          f"{time.perf_counter() - start:.2f} s")
    with user_path(out, "make the folder"):
        out.mkdir(parents=True, exist_ok=True)
    if args.backend == "blender":
        records = _render_blender(args, mesh, out)
    else:
        records = _render_pyrender(args, mesh, skeleton, outputs, out)
    cameras = json.dumps({
        "convention": "opencv: x right, y down, z forward; world Z up, metres; pixel centres at integers",
        "backend": args.backend, "rig": args.rig, "size": args.size, "species": args.species,
        "seed": args.seed, "params": params, "views": records}, indent=1, default=float)
    with user_path(out / "cameras.json", "write"):
        (out / "cameras.json").write_text(cameras)
    print(f"wrote {counted(len(records), 'view')} to {out}")
    return 0
