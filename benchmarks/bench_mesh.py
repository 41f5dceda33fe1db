"""Meshing and export speed on one core: a synthetic 5,000-node, 20,000-leaf tree through build_mesh, GLB and OBJ.

Prints a table of median times beside the reference targets, the mesh sizes, and the glTF validator's verdict.
Run: .venv/bin/python benchmarks/bench_mesh.py [--repeats 20]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT))  # the synthetic tree comes from the tests' skeleton factory

from species.meshing.tubes_and_cards import build_mesh  # noqa: E402
from species.skeleton import Skeleton  # noqa: E402
from tests.species.skeleton_factory import random_tree  # noqa: E402

# Target from the task: a ~5,000-node, ~20k-leaf tree meshes "in well under 50 ms on one core".
REFERENCE_MESH_MS = 50.0


def _median_ms(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times))


def _validator_verdict(glb: bytes) -> str:
    node = shutil.which("node")
    if node is None or not (REPO_ROOT / "node_modules" / "gltf-validator").is_dir():
        return "not run (node or node_modules/gltf-validator missing; run make env)"
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.glb"
        path.write_bytes(glb)
        done = subprocess.run([node, str(REPO_ROOT / "tests/tools/validate_gltf.mjs"), str(path)],
                              capture_output=True, text=True, check=True)
    issues = json.loads(done.stdout)["issues"]
    return f"{issues['numErrors']} errors, {issues['numWarnings']} warnings, {issues['numInfos']} infos"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--nodes", type=int, default=5000)
    parser.add_argument("--leaves", type=int, default=20000)
    args = parser.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, as the target says

    skeleton = random_tree(np.random.default_rng(0), n_nodes=args.nodes, n_leaves=args.leaves)

    def cold_mesh():  # a fresh Skeleton, so its cached branch paths are part of the cost
        fresh = Skeleton(**skeleton.to_arrays())
        return build_mesh(fresh)

    mesh = build_mesh(skeleton)
    glb = mesh.to_glb()  # warms the per-colour texture cache
    mesh.to_obj()
    rows = [
        ("build_mesh, warm skeleton", _median_ms(lambda: build_mesh(skeleton), args.repeats), REFERENCE_MESH_MS),
        ("build_mesh, fresh skeleton", _median_ms(cold_mesh, args.repeats), REFERENCE_MESH_MS),
        ("to_glb (textures cached)", _median_ms(mesh.to_glb, args.repeats), None),
        ("to_obj (textures cached)", _median_ms(mesh.to_obj, max(3, args.repeats // 4)), None),
    ]
    print(f"tree: {skeleton}")
    print(f"mesh: bark {mesh.bark.n_vertices} vertices / {mesh.bark.n_faces} faces, "
          f"leaves {mesh.leaves.n_vertices} vertices / {mesh.leaves.n_faces} faces")
    print(f"{'step':<30}{'median ms':>12}{'reference ms':>14}")
    for name, ms, reference in rows:
        print(f"{name:<30}{ms:>12.1f}{'< %.0f' % reference if reference else '-':>14}")
    print(f"GLB size: {len(glb) / 1e6:.2f} MB; OBJ size: {len(mesh.to_obj()['tree.obj']) / 1e6:.2f} MB")
    print(f"Khronos glTF validator: {_validator_verdict(glb)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
