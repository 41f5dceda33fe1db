"""Self-organizing growth speed on one core: internodes per second, beside the thesis and Palubicki's figures.

The main case grows about 5,000 internodes in a crown of 20,000 markers (space colonization, Borchert-Honda); three
variants beside it, then every colonization preset once. Front views of the cases go to a PNG.
Run: python -m benchmarks.bench_colonization [--runs 5] [--profile] [--png out/bench_colonization.png]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

import cProfile  # noqa: E402
import pstats  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import species  # noqa: E402
from benchmarks.skeleton_drawing import front_view, save_sheet  # noqa: E402
from species.colonization.generator import grow  # noqa: E402

# About 5,000 internodes from 20,000 markers: an ellipsoid crown of ~31,000 IL^3 at 0.65 markers per IL^3.
MAIN = {"generator": "colonization", "crown_shape": "ellipsoid", "crown_radius": 20.0, "crown_height": 34.0,
        "crown_base": 6.0, "marker_density": 0.65, "max_markers": 20000, "iterations": 60, "leaf_age": 0}
CASES = [
    ("space colonization, BH (main)", MAIN),
    ("space colonization, priority", {**MAIN, "allocation": "priority", "kappa": 0.5}),
    ("shadow propagation, BH", {**MAIN, "resource": "shadow"}),
    ("lobe-constrained (4 lobes)", {**MAIN, "crown_shape": "lobes", "crown_lobes": 4}),
]
REFERENCES = [
    "thesis 000, growth per tree (i7-7700HQ): 1.07-1.53 s per tree",
    "thesis 000, lobe-constrained growth: 0.096-0.310 s per tree",
    "Palubicki et al. 2009 (C++), shadow propagation: ~10,700 internodes/s",
    "Palubicki et al. 2009 (C++), space colonization: ~3,600 internodes/s (about 3x slower)",
    "target here, one core: >= 10,000 internodes/s",
]


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--runs", type=int, default=5, help="trees per case, seeds 0..runs-1 (median reported)")
    parser.add_argument("--profile", action="store_true", help="print the top functions of the main case")
    parser.add_argument("--png", type=Path, default=Path("out/bench_colonization.png"))
    args = parser.parse_args()
    bench = Benchmark("colonization", "Self-organizing growth on one core: internodes per second", args)

    grow(MAIN, np.random.default_rng(99))  # warm-up: imports and caches out of the timing
    rows, tiles = [], []
    for name, params in tqdm(CASES, desc="cases", unit="case"):
        seeds, internodes, trees = iter(range(args.runs)), [], []

        def grow_next():
            trees.append(grow(params, np.random.default_rng(next(seeds))))
            internodes.append(len(trees[-1]) - 1)

        timing = time_case(grow_next, args.runs)
        # Growth is single-threaded: CPU time is time on one core, and on a shared machine the steadier figure.
        rates = [int(np.median(np.divide(internodes, seconds))) for seconds in (timing.wall, timing.cpu)]
        rows.append((name, int(np.median(internodes)), timing.median, timing.cpu_median, *rates))
        skeleton = trees[-1]
        tiles.append(front_view(skeleton, f"{name}: {len(skeleton) - 1} internodes", size=420, leaves=False))
    presets = species.list_presets("colonization")
    preset_seconds = []
    for preset in tqdm(presets, desc="presets", unit="preset"):
        params = preset.sample(np.random.default_rng(0))
        preset_seconds.append(time_case(lambda: species.grow(params, species.rng_for(params)), 1).median)
    rows.append((f"presets ({len(presets)}, seed 0), median tree", "", float(np.median(preset_seconds)), "", "", ""))
    bench.table(f"one thread, median of {args.runs} trees",
                ["case", "internodes", "wall s", "cpu s", "internodes/s wall", "internodes/s cpu"], rows,
                notes=[f"presets: slowest tree {max(preset_seconds):.3f} s", *REFERENCES])
    bench.figure("space colonization, main case", rows[0][5], "internodes/s (CPU)", "target >= 10,000")

    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(grow, MAIN, np.random.default_rng(0))
        pstats.Stats(profiler).sort_stats("tottime").print_stats(12)
    save_sheet(tiles, len(tiles), args.png)
    bench.note(f"front views: {args.png}")
    bench.write()


if __name__ == "__main__":
    main()
