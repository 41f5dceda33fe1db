"""L-system presets: nodes, leaves, rewrite-and-turtle time and mesh time per preset, and a contact sheet PNG.

Run: python -m benchmarks.bench_lsystem [--seeds 5] [--png out/lsystem_presets.png]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from tqdm import tqdm  # noqa: E402

import species  # noqa: E402
from benchmarks.skeleton_drawing import front_view, save_sheet  # noqa: E402
from species.lsystem.generator import grow  # noqa: E402
from species.lsystem.presets import PRESETS  # noqa: E402

# Thesis 003 prints no timings. For scale: the self-organizing model of thesis 000 grows a tree in 1.1-1.5 s
# (i7-7700HQ); the task asks for under ~20k nodes per preset tree so trees mesh and render fast.
REFERENCE_GROW_S = "1.1-1.5"
NODE_LIMIT = 20_000


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--seeds", type=int, default=5, help="trees per preset")
    parser.add_argument("--png", type=Path, default=Path("out/lsystem_presets.png"), help="contact sheet path")
    args = parser.parse_args()
    bench = Benchmark("lsystem", "L-system presets: size, growth and meshing time on one core", args)

    rows, tiles = [], []
    for preset in tqdm(PRESETS, desc="presets", unit="preset"):
        nodes, leaves, grow_s, mesh_s = [], [], [], []
        for seed in range(args.seeds):
            params = preset.sample(np.random.default_rng(seed))
            grown = time_case(lambda: grow(params, species.rng_for(params)), 1)
            meshed = time_case(lambda: species.build_mesh(grown.result, params), 1)
            grow_s.append(grown.median)
            mesh_s.append(meshed.median)
            nodes.append(len(grown.result))
            leaves.append(grown.result.n_leaves)
            if seed < 2:
                tiles.append(front_view(grown.result, f"{preset.name} #{seed}"))
        rows.append((preset.name, f"{min(nodes)}-{max(nodes)}", int(np.median(leaves)), np.median(grow_s) * 1e3,
                     max(grow_s) * 1e3, np.median(mesh_s) * 1e3))
    bench.table(f"{args.seeds} seeds per preset, one core",
                ["preset", "nodes min-max", "leaves", "grow ms median", "grow ms max", "mesh ms median"], rows,
                notes=[f"reference: node limit {NODE_LIMIT} per tree; thesis 000 grows a tree in {REFERENCE_GROW_S} "
                       "s (thesis 003 gives no timings)"])
    save_sheet(tiles, 4, args.png)
    bench.note(f"contact sheet: {args.png}")
    bench.write()


if __name__ == "__main__":
    main()
