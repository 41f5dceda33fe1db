"""Seconds per library asset on one core, per stage (grow, LODs, impostor, quality, textures, GLB, USD, OBJ,
previews, Blender outputs if available), GLB size with/without instancing, IoU per level, and 1 vs 2 workers.

Run: PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_library.py [SPECIES ...]
Reference: Sapling alone takes 1.85 s median to grow one mesh (no LODs); target < 1 s per asset without Blender.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time

import numpy as np

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def main(names: list[str]) -> None:
    from farm.library.asset import build_asset
    from farm.library.job import run_library, write_asset_files
    from farm.library.spec import parse_library_spec
    from farm.storage import Location
    from farm.tree_chain import StageTimer, tree_seed
    from renderers.impostor import CoverageRenderer

    spec = parse_library_spec({"species": {n: 1 for n in names}, "formats": ["glb", "usd", "obj", "collision"],
                               "texture_size": 256, "impostor_tile": 128})
    renderer = CoverageRenderer(64)
    stages, figures = [], []
    with tempfile.TemporaryDirectory() as tmp:
        location = Location.resolve(tmp)
        for i, name in enumerate(names):
            timer = StageTimer()
            asset = build_asset(name, tree_seed(0, i), spec, renderer, timer)
            record = write_asset_files(asset, location, spec, renderer, timer)
            stages.append(timer.seconds)
            figures.append((name, record))
    keys = ["grow", "lods", "wind", "impostor", "quality", "textures", "glb", "usd", "obj", "previews", "write"]
    print(f"{'species':22s}" + "".join(f"{k:>9s}" for k in keys) + f"{'total':>8s}{'w/o qual':>9s}")
    for (name, _), sec in zip(figures, stages):
        total = sum(sec.values())
        print(f"{name:22s}" + "".join(f"{sec.get(k, 0):9.3f}" for k in keys)
              + f"{total:8.2f}{total - sec.get('quality', 0) - sec.get('previews', 0):9.2f}")
    print("\nLevels: triangles (share of LOD0), min IoU over 8 azimuths at the switch size")
    for name, record in figures:
        cells = [f"{lv['name']} {lv['triangles']} ({lv['share_of_lod0']:.3f}) IoU {lv['iou_min']:.3f}"
                 for lv in record["levels"]]
        print(f"  {name:20s} " + " | ".join(cells))
    print("\nGLB bytes with / without leaf instancing")
    for name, record in figures:
        s = record["sizes"]
        print(f"  {name:20s} {s['glb']:>10d} / {s['glb_without_instancing']:>10d}  ({s['glb'] / s['glb_without_instancing']:.2f}x)")
    print("\nReference: Sapling grows one mesh in 1.85 s median (no LODs); target: full asset < 1 s per tree on one core")
    small = parse_library_spec({"species": {n: 2 for n in names[:2]}, "formats": ["glb", "usd"], "texture_size": 64,
                                "impostor_tile": 32, "shard_size": 1})
    for workers in (1, 2):
        out = tempfile.mkdtemp()
        start = time.perf_counter()
        run_library(small, out, workers=workers, progress=False)
        print(f"{workers} worker(s): {small.n_trees} assets in {time.perf_counter() - start:.1f} s "
              f"(Ray start included)")
        shutil.rmtree(out)


if __name__ == "__main__":
    main(sys.argv[1:] or ["maple", "palm", "sc_young_sapling", "lsystem_monopodial", "sassafras", "douglas_fir"])
