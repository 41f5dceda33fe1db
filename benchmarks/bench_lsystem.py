"""L-system presets: nodes, leaves, rewrite+turtle time and mesh time per preset, plus a contact sheet PNG.

Run: .venv/bin/python benchmarks/bench_lsystem.py [--seeds 5] [--png out/lsystem_presets.png]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import species  # noqa: E402
from skeleton_drawing import front_view, save_sheet  # noqa: E402
from species.lsystem.generator import grow  # noqa: E402
from species.lsystem.presets import PRESETS  # noqa: E402

# Thesis 003 prints no timings. For scale: the self-organizing model of thesis 000 grows a tree in 1.1-1.5 s
# (i7-7700HQ); the task asks for under ~20k nodes per preset tree so trees mesh and render fast.
REFERENCE_GROW_S = 1.1
NODE_LIMIT = 20_000


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seeds", type=int, default=5, help="trees per preset")
    parser.add_argument("--png", type=Path, default=Path("out/lsystem_presets.png"), help="contact sheet path")
    args = parser.parse_args()

    rows, tiles = [], []
    for preset in tqdm(PRESETS, desc="presets", unit="preset"):
        nodes, leaves, grow_s, mesh_s = [], [], [], []
        for seed in range(args.seeds):
            params = preset.sample(np.random.default_rng(seed))
            start = time.perf_counter()
            skeleton = grow(params, species.rng_for(params))
            grow_s.append(time.perf_counter() - start)
            start = time.perf_counter()
            species.build_mesh(skeleton, params)
            mesh_s.append(time.perf_counter() - start)
            nodes.append(len(skeleton))
            leaves.append(skeleton.n_leaves)
            if seed < 2:
                tiles.append(front_view(skeleton, f"{preset.name} #{seed}"))
        rows.append((preset.name, min(nodes), max(nodes), int(np.median(leaves)), np.median(grow_s) * 1e3,
                     max(grow_s) * 1e3, np.median(mesh_s) * 1e3))

    print(f"\n{'preset':26s} {'nodes min-max':>15s} {'leaves':>7s} {'grow ms med/max':>16s} {'mesh ms':>8s}")
    for name, low, high, leaf, grow_med, grow_max, mesh_med in rows:
        print(f"{name:26s} {low:>7d}-{high:<7d} {leaf:>7d} {grow_med:>8.1f}/{grow_max:<7.1f} {mesh_med:>8.1f}")
    print(f"reference: node limit {NODE_LIMIT} per tree; thesis 000 grows a tree in {REFERENCE_GROW_S}-1.5 s "
          "(thesis 003 gives no timings)")

    save_sheet(tiles, 4, args.png)
    print(f"contact sheet: {args.png}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
