"""Self-organizing growth speed on one core: internodes per second, beside the thesis and Palubicki's figures.

Run: .venv/bin/python benchmarks/bench_colonization.py [--runs 5] [--profile] [--png out/bench_colonization.png]
The main case grows about 5,000 internodes in a crown of 20,000 markers (space colonization, Borchert-Honda).
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"  # one core, before numpy loads

import argparse  # noqa: E402
import cProfile  # noqa: E402
import platform  # noqa: E402
import pstats  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import species  # noqa: E402
from skeleton_drawing import front_view, save_sheet  # noqa: E402
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
    ("thesis 000, growth per tree (i7-7700HQ)", "1.07-1.53 s per tree"),
    ("thesis 000, lobe-constrained growth", "0.096-0.310 s per tree"),
    ("Palubicki et al. 2009 (C++), shadow propagation", "~10,700 internodes/s"),
    ("Palubicki et al. 2009 (C++), space colonization", "~3,600 internodes/s (about 3x slower)"),
    ("target here, one core", ">= 10,000 internodes/s"),
]


def _time_case(params: dict, runs: int) -> tuple[list[float], list[float], list[int], species.Skeleton]:
    """Wall and CPU seconds per tree. Growth is single-threaded, so CPU time is time on one core; on a
    shared machine (other jobs running) it is the steadier of the two."""
    wall, cpu, internodes, skeleton = [], [], [], None
    for run in range(runs):
        start, start_cpu = time.perf_counter(), time.process_time()
        skeleton = grow(params, np.random.default_rng(run))
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
        internodes.append(len(skeleton) - 1)
    return wall, cpu, internodes, skeleton


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--runs", type=int, default=5, help="trees per case (median reported)")
    parser.add_argument("--profile", action="store_true", help="print the top functions of the main case")
    parser.add_argument("--png", type=Path, default=Path("out/bench_colonization.png"))
    args = parser.parse_args()

    grow(MAIN, np.random.default_rng(99))  # warm-up: imports and caches out of the timing
    rows, tiles = [], []
    for name, params in tqdm(CASES, desc="cases", unit="case"):
        wall, cpu, internodes, skeleton = _time_case(params, args.runs)
        rows.append((name, int(np.median(internodes)), float(np.median(wall)), float(np.median(cpu)),
                     float(np.median(np.array(internodes) / np.array(wall))),
                     float(np.median(np.array(internodes) / np.array(cpu)))))
        tiles.append(front_view(skeleton, f"{name}: {len(skeleton) - 1} internodes", size=420, leaves=False))
    preset_seconds = []
    for preset in tqdm(species.list_presets("colonization"), desc="presets", unit="preset"):
        params = preset.sample(np.random.default_rng(0))
        start = time.perf_counter()
        species.grow(params, species.rng_for(params))
        preset_seconds.append(time.perf_counter() - start)

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"\nmachine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, load average "
          f"{load:.1f}, python {platform.python_version()}, one thread; median of {args.runs} trees")
    print(f"{'case':34s} {'internodes':>10s} {'wall s':>8s} {'cpu s':>7s} {'internodes/s wall':>18s} "
          f"{'internodes/s cpu':>17s}")
    for name, internodes, wall, cpu, rate_wall, rate_cpu in rows:
        print(f"{name:34s} {internodes:>10d} {wall:>8.3f} {cpu:>7.3f} {rate_wall:>18,.0f} {rate_cpu:>17,.0f}")
    print(f"{'presets (24, seed 0), wall per tree':34s} {'':>10s} {np.median(preset_seconds):>8.3f} "
          f"(max {max(preset_seconds):.3f} s)")
    print("\nreferences")
    for name, figure in REFERENCES:
        print(f"  {name:50s} {figure}")

    if args.profile:
        profiler = cProfile.Profile()
        profiler.runcall(grow, MAIN, np.random.default_rng(0))
        pstats.Stats(profiler).sort_stats("tottime").print_stats(12)

    save_sheet(tiles, len(tiles), args.png)
    print(f"front views: {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
