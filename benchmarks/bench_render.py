"""Render speed: milliseconds per view of each map and sketch style, and of the farm's default set, on one core.

Tree: the Weber-Penn preset tree closest to 100k triangles; sizes 256 and 608 px; rig tsn4 (4 views). Blender
Cycles beside it when the Blender worker is installed (`make blender-env`).
Run: python -m benchmarks.bench_render [--repeats 3] [--sizes 256,608] [--cycles-views 2] [--no-cycles]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

import tempfile  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import species  # noqa: E402
from renderers import DEFAULT_OUTPUTS, OUTPUTS, ViewRenderer, make_rig  # noqa: E402

TARGET_TRIANGLES = 100_000
CANDIDATES = ("lombardy_poplar", "silver_birch", "bonsai", "balsam_fir", "quaking_aspen")
TARGET_MS = 150.0  # the full default set at 256 px, one core
TARGET_SPEEDUP = 10.0


def pick_tree():
    """The candidate preset tree (seeds 0-3) whose triangle count is closest to TARGET_TRIANGLES."""
    best = None
    for name in CANDIDATES:
        for seed in range(4):
            params = species.sample(name, np.random.default_rng(seed))
            skeleton = species.grow(params, species.rng_for(params))
            mesh = species.build_mesh(skeleton, params)
            score = abs(mesh.n_faces - TARGET_TRIANGLES)
            if best is None or score < best[0]:
                best = (score, f"{name} seed {seed}", mesh, skeleton)
    return best[1:]


def time_outputs(renderer, mesh, skeleton, outputs, repeats: int):
    """Timing per view of rendering `outputs` for the 4 tsn4 views (CPU time of this process, all threads, is the
    figure to compare: on a shared machine wall time includes waiting)."""
    seeds = iter(range(repeats + 1))
    renderer.render(mesh, skeleton, "tsn4", list(outputs), np.random.default_rng(next(seeds)))  # upload, resize
    timing = time_case(lambda: renderer.render(mesh, skeleton, "tsn4", list(outputs),
                                               np.random.default_rng(next(seeds))), repeats)
    return timing.scaled(len(timing.result))


def cycles_ms(mesh, size: int, n_views: int) -> tuple[float | None, str]:
    """Cycles milliseconds per view (1 thread, 16 samples; the median over views after the first, which also
    builds the BVH) or (None, why not)."""
    try:
        from renderers import blender  # needs the Blender worker's venv; reported when missing
    except ImportError as exc:
        return None, f"renderers.blender not importable: {exc}"
    points = np.concatenate([mesh.bark.vertices, mesh.leaves.vertices])
    cameras = make_rig("tsn4", points, size, np.random.default_rng(0))[:n_views]
    try:
        with tempfile.TemporaryDirectory(prefix="bench-cycles-") as tmp:
            photos = blender.render_photos(mesh.to_glb(), cameras, tmp, samples=16, threads=1)
    except (OSError, ValueError, RuntimeError) as exc:  # worker missing or failed: report, do not hide
        return None, f"{type(exc).__name__}: {str(exc).strip().splitlines()[0][:100]}"
    seconds = photos.render_seconds[1:] or photos.render_seconds
    return 1000.0 * float(np.median(seconds)), "ok"


def main() -> None:
    parser = arguments(__doc__, repeats=3)
    parser.add_argument("--sizes", default="256,608", help="image sizes in px, comma separated")
    parser.add_argument("--cycles-views", type=int, default=2,
                        help="views Cycles renders per size, the first not counted (0 = skip)")
    parser.add_argument("--no-cycles", action="store_true")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    bench = Benchmark("render", "Rendering: milliseconds per view on one core", args)
    cv2.setNumThreads(1)

    label, mesh, skeleton = pick_tree()
    bench.note(f"tree: {label}: {mesh.n_faces} triangles (bark {mesh.bark.n_faces}, leaves {mesh.leaves.n_faces}), "
               f"{len(skeleton)} nodes; rig tsn4 (4 views); one core; median of {args.repeats} renders")
    names = (*OUTPUTS, "DEFAULT SET", "ALL OUTPUTS")
    timings = {}
    renderer = ViewRenderer(sizes[0])
    for size, name in tqdm([(size, name) for size in sizes for name in names], desc="timing", unit="run"):
        renderer.size = size
        outputs = DEFAULT_OUTPUTS if name == "DEFAULT SET" else OUTPUTS if name == "ALL OUTPUTS" else (name,)
        timings[name, size] = time_outputs(renderer, mesh, skeleton, outputs, args.repeats)
    renderer.close()
    cycles = {size: (None, "skipped (--no-cycles)") if args.no_cycles or args.cycles_views == 0
              else cycles_ms(mesh, size, args.cycles_views) for size in sizes}

    rows = [[name, *[f"{timings[name, s].ms(cpu=True):.1f} / {timings[name, s].ms():.1f}" for s in sizes],
             f"<= {TARGET_MS:.0f} ms at 256 px" if name == "DEFAULT SET" else ""] for name in names]
    rows.append(["Cycles photo (16 spp, wall)", *[f"{cycles[s][0]:.0f}" if cycles[s][0] else "n/a" for s in sizes],
                 "Blender Cycles CPU, 1 thread, in the worker"])
    notes = [f"Cycles at {s} px: n/a ({cycles[s][1]})" for s in sizes if cycles[s][0] is None]
    notes += [f"{s} px: the default set is {cycles[s][0] / timings['DEFAULT SET', s].ms():.0f}x faster than Cycles, "
              f"wall to wall (target >= {TARGET_SPEEDUP:.0f}x)" for s in sizes if cycles[s][0] is not None]
    bench.table("ms per view, CPU / wall", ["output", *[f"{s} px" for s in sizes], "reference"], rows, notes)
    if 256 in sizes:
        default = timings["DEFAULT SET", 256]
        bench.figure("default render set at 256 px", default.ms(cpu=True), "ms per view (CPU)",
                     f"wall {default.ms():.0f} ms; target <= {TARGET_MS:.0f} ms")
    bench.write()


if __name__ == "__main__":
    main()
