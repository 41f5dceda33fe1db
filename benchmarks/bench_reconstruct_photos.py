"""Photos to trees (issue 24): an orbit of Blender photos of a generated tree through the full SfM path.

The orbit (`--views` photos 360/views degrees apart, alternating 8 and 15 degrees up, Cycles `--samples` per
pixel) is rendered once and cached under ~/.cache/treefarm/bench-photos/ (Cycles takes seconds a photo). Then,
on the same photos, in one run:
1. `from_photos` three ways: poses estimated by incremental mapping and scaled by the tree's true height (no
   cameras.json: what a user with a phone has), estimated then aligned onto cameras.json, and cameras.json's
   poses with triangulation only; per-stage seconds and the points each isolation step leaves.
2. quality against the generated tree's skeleton: Chamfer distance / height, the Smart-Tree F1 AUC, trunk radius
   and height errors, and the share of the tree's isolated points within 10 cm of the reconstructed bark, for ours
   and, on the same isolated cloud, PyTLidar's TreeQSM (installed for the benchmark only).
3. each `--shapes` of the crown ("sparse": from the SfM points; "hull": grown inside the visual hull of the
   photos' tree masks, issue 51): crown and silhouette IoU in the unseen views of `farm evaluate`
   (`reconstruct.scoring.TreeScorer`), the height error and the seconds of the hull's stages.

Run: python -m benchmarks.bench_reconstruct_photos [--views 36] [--size 640] [--tree sc_broad_oak:0] [--leafless]
     [--max-features 4096] [--matcher sequential] [--ways estimated,aligned,known] [--shapes sparse,hull]
     [--masks network|classical]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

import dataclasses  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402
import shutil  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import species  # noqa: E402
from benchmarks.bench_reconstruct_cloud import QUALITY_COLUMNS, message_row, quality_row, scores  # noqa: E402
from benchmarks.pytlidar_qsm import PyTLidarFailed, pytlidar_missing, pytlidar_run  # noqa: E402
from reconstruct.from_photos import from_photos  # noqa: E402
from reconstruct.metrics import MetricError  # noqa: E402
from reconstruct.scoring import TreeScorer  # noqa: E402
from renderers import ViewRenderer  # noqa: E402
from reconstruct.sfm import PhotoError, SfmSettings  # noqa: E402
from renderers.blender import render_photos  # noqa: E402
from renderers.camera import perspective_camera  # noqa: E402
from species.tree_mesh import MeshPart  # noqa: E402

CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "treefarm" / "bench-photos"
PYTLIDAR_TIMEOUT_S = 300
SHAPE_COLUMNS = ["way, shape", "crown IoU unseen", "silhouette IoU unseen", "height error",
                 "masks s", "hull s", "growth s", "total s"]
WAYS_COLUMNS = ["way", "registered", "reprojection px", "SfM points", "colour", "ground", "footprint", "group",
                "outliers", "stem", "features s", "matching s", "mapping s", "tree s", "total s"]


def orbit(preset: str, seed: int, views: int, size: int, samples: int, leafless: bool
          ) -> tuple[Path, species.Skeleton]:
    """The cached orbit's folder (photos and cameras.json) and the tree's true skeleton."""
    skeleton, mesh = species.rebuild(species.sample(preset, np.random.default_rng(seed)))
    if leafless:
        mesh = dataclasses.replace(mesh, leaves=MeshPart.empty())
    folder = CACHE / f"{preset}-{seed}-{views}x{size}-{samples}spp{'-leafless' if leafless else ''}"
    if not (folder / "cameras.json").is_file():
        points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
        cameras = [perspective_camera(points, k * 360.0 / views, 15.0 if k % 2 else 8.0, size, name=f"view{k}")
                   for k in range(views)]
        partial = folder.with_name(folder.name + ".partial")
        shutil.rmtree(partial, ignore_errors=True)
        started = time.perf_counter()
        render_photos(mesh.to_glb(), cameras, partial, samples=samples)
        print(f"rendered {views} photos at {size} px in {time.perf_counter() - started:.0f} s -> {folder}")
        partial.replace(folder)
    return folder, skeleton


def photos_only(folder: Path) -> Path:
    """A copy of the orbit's photos without cameras.json, depth or masks: what a camera gives."""
    bare = folder.with_name(folder.name + "-bare")
    if not bare.is_dir():
        bare.mkdir()
        for photo in sorted(folder.glob("view_???.png")):
            shutil.copy(photo, bare / photo.name)
    return bare


def ways_row(label: str, result, total: float) -> list:
    """A row of the ways table: the SfM record's counts and the seconds of each stage."""
    record, t = result.scan.provenance["sfm"], result.timings
    counts = record["points"]
    tree_s = sum(v for k, v in t.items() if not k.startswith("sfm."))
    mapping = t.get("sfm.mapping", t.get("sfm.triangulation", 0.0))
    return [label, f"{record['registered']}/{record['photos']}", f"{record['reprojection_px']:.2f}", counts["sfm"],
            counts["colour"], counts["ground"], counts["footprint"], counts["cluster"], counts["outliers"],
            counts["stem"], f"{t['sfm.features']:.1f}", f"{t['sfm.matching']:.1f}", f"{mapping:.1f}",
            f"{tree_s:.2f}", f"{total:.1f}"]


def shape_table(ways: list, args, folder: Path, true: species.Skeleton) -> list[list]:
    """Rows of the shapes table: each way's `--shapes` reconstructions scored in the unseen views."""
    shapes = [s for s in args.shapes.split(",") if s]
    preset, seed = args.tree.split(":")
    _, mesh = species.rebuild(species.sample(preset, np.random.default_rng(int(seed))))
    if args.leafless:
        mesh = dataclasses.replace(mesh, leaves=MeshPart.empty())
    base = true.positions[0]
    moved = dataclasses.replace(mesh, bark=dataclasses.replace(mesh.bark, vertices=mesh.bark.vertices - base),
                                leaves=dataclasses.replace(mesh.leaves, vertices=mesh.leaves.vertices - base))
    true_here = species.Skeleton(true.positions - base, true.parent, true.radius, true.order)
    cameras = json.loads((folder / "cameras.json").read_text())["views"]
    renderer = ViewRenderer(256)
    try:
        scorer = TreeScorer(renderer, true_here, moved, [], [k * 360.0 / len(cameras) for k in range(len(cameras))])
        rows = []
        for label, source, poses, height in ways:
            settings = SfmSettings(poses=poses, threads=args.threads, max_features=args.max_features,
                                   matcher=args.matcher)
            for shape in shapes:
                try:
                    timing = time_case(lambda: from_photos(source, height=height, settings=settings, shape=shape,
                                                           masks=args.masks), repeats=1)
                except PhotoError as error:
                    rows.append([f"{label}, {shape}", f"failed: {error}"] + [""] * (len(SHAPE_COLUMNS) - 2))
                    continue
                result, t = timing.result, timing.result.timings
                row = scorer(result.skeleton, result.mesh)
                rows.append([f"{label}, {shape}", f"{row['crown_iou_unseen']:.3f}",
                             f"{row['silhouette_iou_unseen']:.3f}",
                             f"{row['height_rel_error']:.3f}", f"{t.get('hull.masks', 0.0):.2f}",
                             f"{t.get('hull.hull', 0.0):.2f}", f"{t.get('hull.growth', 0.0):.2f}",
                             f"{timing.median:.1f}"])
                print(rows[-1], flush=True)
        return rows
    finally:
        renderer.close()


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--views", type=int, default=36)
    parser.add_argument("--size", type=int, default=640)
    parser.add_argument("--samples", type=int, default=4)
    parser.add_argument("--tree", default="sc_broad_oak:0", help="PRESET:SEED of the generated tree")
    parser.add_argument("--threads", type=int, default=0, help="pycolmap threads (0 = all CPUs)")
    parser.add_argument("--max-features", type=int, default=4096,
                        help="SIFT features a photo (matching costs grow with their square)")
    parser.add_argument("--matcher", default="sequential", choices=("sequential", "exhaustive", "auto"),
                        help="sequential (each photo with the next 10, for an orbit: the default) or exhaustive")
    parser.add_argument("--pytlidar-timeout", type=float, default=PYTLIDAR_TIMEOUT_S)
    parser.add_argument("--leafless", action="store_true", help="the tree in winter: bark only")
    parser.add_argument("--render-only", action="store_true")
    parser.add_argument("--ways", default="estimated,aligned,known",
                        help="which poses to run: estimated (scaled by the height), aligned, known")
    parser.add_argument("--shapes", default="sparse,hull",
                        help="crowns to compare in unseen views: sparse, hull (comma-separated)")
    parser.add_argument("--masks", default="network", choices=("network", "classical"),
                        help="the hull's tree masks: the tree mask network (default) or classical")
    args = parser.parse_args()
    preset, seed = args.tree.split(":")
    folder, true = orbit(preset, int(seed), args.views, args.size, args.samples, args.leafless)
    if args.render_only:
        return
    bench = Benchmark("reconstruct_photos", "Photos to trees: an orbit of Blender photos through SfM", args)
    ways = {"estimated": ("estimated, scaled by the height", photos_only(folder), "auto", true.height),
            "aligned": ("estimated, aligned to cameras.json", folder, "estimate", None),
            "known": ("known poses (cameras.json)", folder, "known", None)}
    ways = [ways[w] for w in args.ways.split(",")]
    shape_rows = shape_table(ways, args, folder, true)
    rows, results = [], []
    for label, source, poses, height in ways:
        settings = SfmSettings(poses=poses, threads=args.threads, max_features=args.max_features,
                               matcher=args.matcher)
        try:
            timing = time_case(lambda: from_photos(source, height=height, settings=settings), repeats=1)
        except PhotoError as error:
            rows.append([label, f"failed: {error}"] + [""] * (len(WAYS_COLUMNS) - 2))
            continue
        rows.append(ways_row(label, timing.result, timing.median))
        results.append((label, timing.result, timing.median))
    bench.table(f"{args.views} photos of {preset} #{seed} ({true.height:.1f} m) at {args.size} px, {args.samples} "
                f"spp{', leafless' if args.leafless else ', in leaf'}; {args.matcher} matching, {args.max_features} "
                "features a photo", WAYS_COLUMNS, rows)
    missing = pytlidar_missing(args.pytlidar_timeout)
    base = true.positions[0]
    true_here = species.Skeleton(true.positions - base, true.parent, true.radius, true.order)
    height, rows = f"{true.height:.1f}", []
    for label, result, total in results:
        # Both trees in the base frame: ours has its root at the origin; the isolated cloud is shifted the same.
        scan = result.scan
        shift = (scan.transform[:3, 3] - scan.cloud.offset).astype(np.float32)
        cloud = scan.cloud.points - shift
        rows.append(quality_row(f"{label}, ours", height,
                                scores(scan.measured, scan.measures["trunk_radius_fit_m"], true, true_here, cloud,
                                       total)))
        if missing is not None:
            rows.append(message_row(f"{label}, PyTLidar", "", missing))
            continue
        try:
            run = pytlidar_run(cloud, args.pytlidar_timeout)
            rows.append(quality_row(f"{label}, PyTLidar", height,
                                    scores(run.skeleton, float(run.skeleton.radius[0]), true, true_here, cloud,
                                           run.seconds)))
        except (PyTLidarFailed, MetricError) as error:
            rows.append(message_row(f"{label}, PyTLidar", "", f"failed: {error}"))
    bench.table("quality against the generated tree's skeleton (the base at the origin, as `frame='base'`)",
                ["way, method", *QUALITY_COLUMNS], rows)
    if shape_rows:
        bench.table("crowns in the unseen views of `farm evaluate` (orbit:8:0, the azimuths no photo looked along)",
                    SHAPE_COLUMNS, shape_rows)
    bench.note("SfM records: " + json.dumps({label: r.scan.provenance["sfm"] for label, r, _ in results}))
    bench.write()


if __name__ == "__main__":
    main()
