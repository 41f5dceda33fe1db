"""Grow-and-mesh speed of the Weber-Penn generator on one core, beside Blender's Sapling add-on.

For each TreeSketchNet dictionary in ../shared/data/sapling and each Weber-Penn preset: median seconds to grow and
mesh one tree, vertex and face counts, height and crown radius. Run: .venv/bin/python benchmarks/bench_weber_penn.py
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import species  # noqa: E402
from farm.table import format_table  # noqa: E402

SAPLING_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "sapling"
# Blender Sapling 0.3.4 on this machine: seconds to grow one mesh where measured, height and crown radius.
SAPLING = json.loads((Path(__file__).resolve().parent / "references" / "sapling.json").read_text())
SAPLING_MEDIAN_SECONDS = SAPLING["median_seconds"]


def time_tree(params: dict, repeats: int) -> tuple[float, float, float, object, object]:
    """Median seconds of grow, of mesh, and of both, over `repeats` runs; plus the last skeleton and mesh."""
    grow_s, mesh_s = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        skeleton = species.grow(params, species.rng_for(params))
        t1 = time.perf_counter()
        mesh = species.build_mesh(skeleton, params)
        t2 = time.perf_counter()
        grow_s.append(t1 - t0)
        mesh_s.append(t2 - t1)
    total = [g + m for g, m in zip(grow_s, mesh_s)]
    return statistics.median(grow_s), statistics.median(mesh_s), statistics.median(total), skeleton, mesh


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    species.build_mesh(species.grow(species.sample("maple", np.random.default_rng(0)), np.random.default_rng(0)))

    rows, totals = [], []
    for path in sorted(SAPLING_DIR.glob("*.json")):
        params = json.loads(path.read_text())
        g, m, t, skeleton, mesh = time_tree(params, args.repeats)
        totals.append(t)
        reference = SAPLING["trees"][path.stem]
        ref_h, ref_c = reference["height_m"], reference["crown_radius_m"]
        sapling = reference.get("seconds")
        rows.append((path.stem, round(g * 1000, 1), round(m * 1000, 1), round(t * 1000, 1),
                     f"{sapling:.2f}" if sapling else "-", f"{sapling / t:.0f}x" if sapling else "-",
                     mesh.n_vertices, mesh.n_faces, f"{skeleton.height:.2f} / {ref_h:.2f}",
                     f"{skeleton.crown_radius:.2f} / {ref_c:.2f}"))
    print("TreeSketchNet dictionaries (one core; Sapling 0.3.4 in Blender on this machine beside it)")
    print(format_table(["dictionary", "grow_ms", "mesh_ms", "total_ms", "sapling_s", "speedup", "vertices", "faces",
                        "height ours/sapling", "crown ours/sapling"], rows))
    median = statistics.median(totals)
    print(f"\nmedian over the five dictionaries: {median * 1000:.1f} ms per tree; Sapling {SAPLING_MEDIAN_SECONDS} s "
          f"-> {SAPLING_MEDIAN_SECONDS / median:.0f}x faster (target >= 20x per dictionary)\n")

    rows = []
    for preset in species.list_presets("weber_penn"):
        params = species.sample(preset, np.random.default_rng(0))
        g, m, t, skeleton, mesh = time_tree(params, args.repeats)
        rows.append((preset.name, round(g * 1000, 1), round(m * 1000, 1), round(t * 1000, 1), mesh.n_vertices,
                     mesh.n_faces, round(skeleton.height, 2), round(skeleton.crown_radius, 2)))
    print("Weber-Penn presets (seed 0, one core)")
    print(format_table(["preset", "grow_ms", "mesh_ms", "total_ms", "vertices", "faces", "height_m", "crown_m"], rows))


if __name__ == "__main__":
    main()
