"""Grow-and-mesh speed of the Weber-Penn generator on one core, beside Blender's Sapling add-on.

For each TreeSketchNet dictionary (the shared data's `sapling/` folder) and each Weber-Penn preset: median
milliseconds to grow and to mesh one tree, vertex and face counts, height and crown radius, and for the
dictionaries Sapling's seconds, height and crown radius (`fixtures/references/sapling.json`).
Run: python -m benchmarks.bench_weber_penn [--repeats 7]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

import json  # noqa: E402
import statistics  # noqa: E402

import numpy as np  # noqa: E402

import species  # noqa: E402
from fixtures.sapling import TSN_DICTS, sapling_reference  # noqa: E402


def time_tree(params: dict, repeats: int) -> tuple[float, float, object, object]:
    """Median seconds of growing and of meshing the tree over `repeats` runs; its skeleton and mesh."""
    grown = time_case(lambda: species.grow(params, species.rng_for(params)), repeats)
    meshed = time_case(lambda: species.build_mesh(grown.result, params), repeats)
    return grown.median, meshed.median, grown.result, meshed.result


def main() -> None:
    args = arguments(__doc__, repeats=7).parse_args()
    bench = Benchmark("weber_penn", "Weber-Penn grow and mesh on one core, beside Sapling", args)
    species.build_mesh(species.grow(species.sample("maple", np.random.default_rng(0)), np.random.default_rng(0)))

    dictionaries = sorted(TSN_DICTS.glob("*.json"))
    if dictionaries:
        sapling = sapling_reference()
        rows, totals = [], []
        for path in dictionaries:
            params = json.loads(path.read_text())
            grow_s, mesh_s, skeleton, mesh = time_tree(params, args.repeats)
            total = grow_s + mesh_s
            totals.append(total)
            reference = sapling["trees"][path.stem]
            seconds = reference.get("seconds")
            rows.append((path.stem, 1000 * grow_s, 1000 * mesh_s, 1000 * total, seconds or "-",
                         f"{seconds / total:.0f}x" if seconds else "-", mesh.n_vertices, mesh.n_faces,
                         f"{skeleton.height:.2f} / {reference['height_m']:.2f}",
                         f"{skeleton.crown_radius:.2f} / {reference['crown_radius_m']:.2f}"))
        bench.table("TreeSketchNet dictionaries, one core (Sapling 0.3.4 in Blender beside it)",
                    ["dictionary", "grow ms", "mesh ms", "total ms", "Sapling s", "speed-up", "vertices", "faces",
                     "height m ours / Sapling", "crown m ours / Sapling"], rows)
        median = statistics.median(totals)
        bench.figure("median grow + mesh over the dictionaries", 1000 * median, "ms per tree")
        bench.figure("speed-up on Sapling's median", sapling["median_seconds"] / median, "x",
                     f"Sapling {sapling['median_seconds']} s per tree; target >= 20x per dictionary")
    else:
        bench.note(f"no TreeSketchNet dictionaries in {TSN_DICTS}: the Sapling comparison is skipped")

    rows, totals = [], []
    for preset in species.list_presets("weber_penn"):
        params = species.sample(preset, np.random.default_rng(0))
        grow_s, mesh_s, skeleton, mesh = time_tree(params, args.repeats)
        totals.append(grow_s + mesh_s)
        rows.append((preset.name, 1000 * grow_s, 1000 * mesh_s, 1000 * (grow_s + mesh_s), mesh.n_vertices,
                     mesh.n_faces, skeleton.height, skeleton.crown_radius))
    bench.table("Weber-Penn presets (seed 0, one core)",
                ["preset", "grow ms", "mesh ms", "total ms", "vertices", "faces", "height m", "crown m"], rows)
    bench.figure("presets grown and meshed per second", 1 / statistics.median(totals), "trees/s",
                 "one core, the median preset")
    bench.write()


if __name__ == "__main__":
    main()
