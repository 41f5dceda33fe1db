"""The Blender side of the Sapling differential harness: grow dictionaries with Blender's Sapling add-on over seeds.

In: a JSON file {"dictionaries": {name: params}} (written by bench_sapling_fidelity.py). Out: one JSON line per
(dictionary, seed) appended to --out: seconds, bark height and crown radius (m), stems per level, leaf count.
Run with the Blender Python: .venv-blender/bin/python benchmarks/sapling_runner.py --seeds 24 --out F DICTS.json
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path

import numpy as np

SAPLING_DIR = Path(__file__).resolve().parents[2] / "shared" / "tools" / "sapling"
sys.path.insert(0, str(SAPLING_DIR))
import bpy  # noqa: E402
import add_curve_sapling as sapling  # noqa: E402
from add_curve_sapling import utils as sapling_utils  # noqa: E402

# Faces Sapling's genLeafMesh makes per leaf, by leafShape ('dVert' leaves are single vertices, counted as such).
FACES_PER_LEAF = {"hex": 2, "rect": 1, "dFace": 1}


class _LevelCounter:
    """Counts the splines of Sapling's tree curve as each level starts growing, by wrapping the two functions
    addTree calls once per level (kickstart_trunk for the trunk, fabricate_stems for each later level)."""

    def __init__(self) -> None:
        self.curve = None
        self.at_level_start: list[int] = []
        self._originals = {name: getattr(sapling_utils, name) for name in ("kickstart_trunk", "fabricate_stems")}

    def install(self) -> None:
        for name, original in self._originals.items():
            setattr(sapling_utils, name, self._wrap(original))

    def _wrap(self, original):
        def counted(*args, **kwargs):
            curve = next(a for a in args if isinstance(a, bpy.types.Curve))
            self.curve = curve
            self.at_level_start.append(len(curve.splines))
            return original(*args, **kwargs)
        return counted

    def reset(self) -> None:
        self.curve, self.at_level_start = None, []

    def stems_per_level(self) -> list[int]:
        """Splines added by each level (a split's new splines count with their level, as in Sapling's curve)."""
        if self.curve is None:
            return []
        counts = np.diff(np.asarray(self.at_level_start + [len(self.curve.splines)]))
        return counts.astype(int).tolist()


class _Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise _Timeout("tree took longer than the per-tree limit")


def _vertices(obj, graph) -> np.ndarray:
    """(V, 3) float64 world coordinates of an object's evaluated mesh (a curve's bevelled tube included)."""
    mesh = obj.evaluated_get(graph).to_mesh()
    co = np.empty(len(mesh.vertices) * 3, np.float64)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    matrix = np.array(obj.matrix_world, np.float64)
    return co @ matrix[:3, :3].T + matrix[:3, 3]


def grow_one(params: dict, counter: _LevelCounter, limit_s: int) -> dict:
    """One Sapling tree in a fresh scene: its figures, measured as shared/tools/sapling/run_sapling.py does."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    sapling.register()
    counter.reset()
    try:
        props = set(bpy.ops.curve.tree_add.get_rna_type().properties.keys())
        kwargs = {k: v for k, v in params.items() if k in props}
        kwargs.update(showLeaves=True, do_update=True)
        signal.alarm(limit_s)
        start = time.perf_counter()
        try:
            bpy.ops.curve.tree_add(**kwargs)
        finally:
            seconds = time.perf_counter() - start
            signal.alarm(0)
        graph = bpy.context.evaluated_depsgraph_get()
        bark = np.zeros((0, 3))
        leaf_faces = leaf_vertices = 0
        for obj in list(bpy.data.objects):
            if obj.name == "tree":
                bark = _vertices(obj, graph)
            elif obj.name.startswith("leaves"):
                mesh = obj.evaluated_get(graph).to_mesh()
                leaf_faces += len(mesh.polygons)
                leaf_vertices += len(mesh.vertices)
        shape = kwargs.get("leafShape", bpy.ops.curve.tree_add.get_rna_type().properties["leafShape"].default)
        leaves = leaf_faces // FACES_PER_LEAF[shape] if shape in FACES_PER_LEAF else leaf_vertices
        height = float(bark[:, 2].max() - bark[:, 2].min()) if len(bark) else 0.0
        crown = float(np.sqrt((bark[:, :2] ** 2).sum(axis=1)).max()) if len(bark) else 0.0
        return {"seconds": round(seconds, 4), "bark_height_m": round(height, 4), "crown_radius_m": round(crown, 4),
                "stems_per_level": counter.stems_per_level(), "leaves": int(leaves)}
    finally:
        sapling.unregister()


def versions() -> dict:
    """Blender's and the add-on's versions, recorded beside the figures, and the add-on's keys (the only ones of a
    dictionary that reach it)."""
    sapling.register()
    try:
        keys = sorted(set(bpy.ops.curve.tree_add.get_rna_type().properties.keys()) - {"rna_type", "seed"})
    finally:
        sapling.unregister()
    return {"blender": bpy.app.version_string, "sapling": ".".join(map(str, sapling.bl_info["version"])),
            "python": sys.version.split()[0], "sapling_keys": keys}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dicts", type=Path, help='JSON file {"dictionaries": {name: params}}')
    parser.add_argument("--seeds", type=int, default=24)
    parser.add_argument("--out", type=Path, required=True, help="JSON lines, appended; done (name, seed) skipped")
    parser.add_argument("--limit-s", type=int, default=300, help="seconds one tree may take before it is given up")
    parser.add_argument("--versions", action="store_true", help="print the versions as one JSON line and exit")
    args = parser.parse_args()
    if args.versions:
        print(json.dumps(versions()))
        return
    dictionaries = json.loads(args.dicts.read_text())["dictionaries"]
    done = set()
    if args.out.exists():
        for line in args.out.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                done.add((row["name"], row["seed"]))
    signal.signal(signal.SIGALRM, _alarm)
    counter = _LevelCounter()
    counter.install()
    # Seeds in rounds of 8 over all dictionaries, so that a run cut short still covers every dictionary.
    rounds = [range(s, min(s + 8, args.seeds)) for s in range(0, args.seeds, 8)]
    with args.out.open("a") as out:
        for seeds in rounds:
            for name, params in dictionaries.items():
                for seed in seeds:
                    if (name, seed) in done:
                        continue
                    try:
                        row = grow_one({**params, "seed": seed}, counter, args.limit_s)
                    except (RuntimeError, _Timeout) as exc:  # Sapling's own failure, reported through bpy.ops
                        row = {"error": str(exc).strip().splitlines()[-1][:300]}
                    out.write(json.dumps({"name": name, "seed": seed, **row}) + "\n")
                    out.flush()


if __name__ == "__main__":
    main()
