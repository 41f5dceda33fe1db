"""Meshing and export speed on one core: a synthetic 5,000-node, 20,000-leaf tree (`fixtures.skeletons`) through
build_mesh, GLB and OBJ, beside the target; the mesh sizes and the Khronos glTF validator's verdict.

Run: python -m benchmarks.bench_mesh [--repeats 20] [--nodes 5000] [--leaves 20000]
"""
from __future__ import annotations

from benchmarks.harness import ROOT, Benchmark, arguments, pin_threads, time_case

pin_threads(one_core=True)

import json  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from fixtures.skeletons import random_tree  # noqa: E402
from species.meshing.tubes_and_cards import build_mesh  # noqa: E402
from species.skeleton import Skeleton  # noqa: E402

# The target: a ~5,000-node, ~20k-leaf tree meshes "in well under 50 ms on one core".
REFERENCE_MESH_MS = 50.0


def validator_verdict(glb: bytes) -> str:
    node = shutil.which("node")
    if node is None or not (ROOT / "node_modules" / "gltf-validator").is_dir():
        return "not run (node or node_modules/gltf-validator missing; run make env)"
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "bench.glb"
        path.write_bytes(glb)
        done = subprocess.run([node, str(ROOT / "tests/tools/validate_gltf.mjs"), str(path)],
                              capture_output=True, text=True, check=True)
    issues = json.loads(done.stdout)["issues"]
    return f"{issues['numErrors']} errors, {issues['numWarnings']} warnings, {issues['numInfos']} infos"


def main() -> None:
    parser = arguments(__doc__, repeats=20)
    parser.add_argument("--nodes", type=int, default=5000)
    parser.add_argument("--leaves", type=int, default=20000)
    args = parser.parse_args()
    bench = Benchmark("mesh", "Meshing and export of a 5,000-node, 20,000-leaf tree on one core", args)
    skeleton = random_tree(np.random.default_rng(0), n_nodes=args.nodes, n_leaves=args.leaves)

    def cold_mesh():  # a fresh Skeleton, so its cached branch paths are part of the cost
        return build_mesh(Skeleton(**skeleton.to_arrays()))

    mesh = build_mesh(skeleton)
    glb = mesh.to_glb()  # warms the per-colour texture cache
    obj = mesh.to_obj()
    steps = [("build_mesh, warm skeleton", time_case(lambda: build_mesh(skeleton), args.repeats), REFERENCE_MESH_MS),
             ("build_mesh, fresh skeleton", time_case(cold_mesh, args.repeats), REFERENCE_MESH_MS),
             ("to_glb (textures cached)", time_case(mesh.to_glb, args.repeats), None),
             ("to_obj (textures cached)", time_case(mesh.to_obj, max(3, args.repeats // 4)), None)]
    bench.note(f"tree: {skeleton}; mesh: bark {mesh.bark.n_vertices} vertices / {mesh.bark.n_faces} faces, "
               f"leaves {mesh.leaves.n_vertices} vertices / {mesh.leaves.n_faces} faces")
    bench.table("median ms per step, one core",
                ["step", "median ms", "spread", "reference ms"],
                [(name, timing, f"{timing.spread:.0%}", f"< {reference:.0f}" if reference else "-")
                 for name, timing, reference in steps])
    bench.figure("build_mesh of the 5,000-node, 20,000-leaf tree", steps[1][1].ms(), "ms",
                 f"target < {REFERENCE_MESH_MS:.0f} ms")
    bench.note(f"GLB size: {len(glb) / 1e6:.2f} MB; OBJ size: {len(obj['tree.obj']) / 1e6:.2f} MB")
    bench.note(f"Khronos glTF validator: {validator_verdict(glb)}")
    bench.write()


if __name__ == "__main__":
    main()
