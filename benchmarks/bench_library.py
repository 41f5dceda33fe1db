"""Seconds per library asset on one core, per stage (grow, LODs, twig cards, wind, textures, impostor, quality, GLB,
USD, OBJ, previews), triangles and least silhouette IoU per level beside its half-pixel floor, GLB bytes with and
without leaf instancing and twig cards, and the speed-up of 2 workers over 1.

IoU rule (renderers/alpha_coverage.py): every leaf and cluster card drawn as its two triangles shrunk about its
centre to the opaque share of its alpha tile, in depth-only passes that cull only the bark's back faces (as its
single-sided material does; leaves and twig cards are double-sided); the impostor cut by its atlas alpha.
bench_silhouette_floor.py says what the measure itself allows at each switch size. Seeds are tree_seed(0, position
in the list): compare figures only between runs of the same list.
Reference: Sapling alone takes 1.85 s median to grow one mesh (no LODs); target < 1 s per asset without Blender.
Run: PYOPENGL_PLATFORM=egl python -m benchmarks.bench_library [SPECIES ...] [--no-scaling] [--no-twig-cards]
(the last: the spec's `twig_cards: false`, levels of tubes and leaf cards only)
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case, unpin_cores

pin_threads(one_core=True)

import dataclasses  # noqa: E402
import os  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402
import ray  # noqa: E402

from farm.dataset.storage import Location  # noqa: E402
from farm.library.asset import build_asset  # noqa: E402
from farm.library.gltf_asset import glb_size  # noqa: E402
from farm.library.job import run_library, write_asset_files  # noqa: E402
from farm.library.quality import FLOOR_MARGIN, asset_floors  # noqa: E402
from farm.library.spec import parse_library_spec  # noqa: E402
from farm.tree_chain import tree_seed  # noqa: E402
from renderers.gl_coverage import CoverageRenderer  # noqa: E402
from species.meshing.png import png_bytes  # noqa: E402
from species.timing import StageTimer  # noqa: E402

DEFAULT_SPECIES = ("maple", "pine", "cherry", "palm", "sc_young_sapling", "lsystem_monopodial", "sassafras",
                   "douglas_fir", "balsam_fir")
WARM_UP = "bonsai"  # a species outside the list, so no texture cache is warmed for the measured ones
SCALING_SPECIES = ("palm", "sc_young_sapling", "sassafras", "lsystem_monopodial")
STAGES = ("grow", "lods", "twigs", "wind", "textures", "impostor", "quality", "glb", "usd", "obj", "previews", "write")
BUDGETS = {"LOD1": 0.40, "LOD2": 0.12, "LOD3": 0.04}


def stage_table(bench: Benchmark, names: list[str], stages: list[dict]) -> None:
    totals = [sum(sec.values()) for sec in stages]
    bench.table("seconds per asset and stage, one core",
                ["species", *STAGES, "total", "w/o quality"],
                [(name, *[sec.get(k, 0.0) for k in STAGES], total, total - sec.get("quality", 0.0))
                 for name, sec, total in zip(names, stages, totals)],
                notes=["w/o quality: without the IoU measurement", "target < 1 s per asset without Blender outputs; "
                       "Sapling grows one mesh in 1.85 s median (no LODs)"])
    bench.figure("median seconds per full asset", float(np.median(totals)), "s",
                 "one core, every file but Blender's; target < 1 s")


def level_table(bench: Benchmark, records: list[tuple[str, dict]], floors: dict) -> None:
    rows = []
    for name, record in records:
        rows.append((name, "LOD0", record["levels"][0]["triangles"], 1.0, "", "", ""))
        for level in record["levels"][1:]:
            floor = floors[name][level["name"]]
            over = level["share_of_lod0"] > BUDGETS.get(level["name"], 1.0) or (
                level["name"] == "IMPOSTOR" and level["triangles"] > 16)
            rows.append((name, level["name"], level["triangles"], f"{level['share_of_lod0']:.3f}{'*' if over else ''}",
                         f"{level['iou_min']:.3f}{'*' if level['iou_min'] < 0.9 else ''}", f"{floor.floor:.3f}",
                         f"{floor.margin:+.3f}{'' if floor.meets else '!'}"))
    bench.table("levels: triangles, least IoU over 8 azimuths at the switch size, the half-pixel floor",
                ["species", "level", "triangles", "share of LOD0", "least IoU", "floor", "margin"], rows,
                notes=["budgets 0.40/0.12/0.04 of LOD0, impostor <= 16 triangles; IoU target >= 0.9; "
                       f"floor target: margin >= -{FLOOR_MARGIN}",
                       "* misses the budget or the IoU target, ! misses the floor target"])


def glb_tables(bench: Benchmark, names: list[str], records: list[tuple[str, dict]], spec, renderer,
               twig_cards: bool) -> None:
    bench.table("GLB bytes with and without leaf instancing", ["species", "instanced", "baked", "ratio"],
                [(name, r["sizes"]["glb"], r["sizes"]["glb_without_instancing"],
                  r["sizes"]["glb"] / r["sizes"]["glb_without_instancing"]) for name, r in records])
    if not twig_cards:
        return
    plain = dataclasses.replace(spec, twig_cards=False)
    rows = []
    for i, name in enumerate(names):
        asset = build_asset(name, tree_seed(0, i), spec, renderer, StageTimer())
        if asset.twig_atlas is None:
            rows.append((name, "no twig cards", "", "", ""))
            continue
        with_twigs = glb_size(asset)
        atlas_bytes = sum(len(png_bytes(image, palette=True)) for image in asset.twig_albedos.values()) \
            + len(png_bytes(asset.twig_atlas.normal))
        without = glb_size(build_asset(name, tree_seed(0, i), plain, renderer, StageTimer()))
        rows.append((name, with_twigs, without, f"{100 * (with_twigs / without - 1):+.1f} %",
                     f"{atlas_bytes} B = {100 * atlas_bytes / without:.1f} %"))
    bench.table("GLB bytes with twig cards and without them (`twig_cards: false`), and the twig atlas's images",
                ["species", "with twig cards", "without", "growth", "atlas images, share of the GLB without"], rows,
                notes=["the twig atlas (four albedos, the normal map) may grow the GLB by at most 25 %"])


def scaling(bench: Benchmark) -> None:
    """Seconds of a small library job on 1 and on 2 workers, each on a fresh local Ray of exactly that many CPUs."""
    small = parse_library_spec({"species": {n: 4 for n in SCALING_SPECIES}, "formats": ["glb", "usd"],
                                "texture_size": 64, "impostor_tile": 32, "shard_size": 2})
    unpin_cores()  # the per-asset figures are taken on one core; the workers get every core of the machine
    elapsed = {}
    for workers in (1, 2):
        out = tempfile.mkdtemp()
        ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level="WARNING",
                 runtime_env={"env_vars": {"PYOPENGL_PLATFORM": "egl"}})
        elapsed[workers] = time_case(lambda: run_library(small, out, workers=workers, progress=False), 1).median
        ray.shutdown()
        shutil.rmtree(out)
    # Long enough that actor start-up (a few seconds per worker) does not hide the scaling.
    bench.table(f"a library job of {small.n_trees} small assets, actor start included", ["workers", "seconds"],
                [(workers, seconds) for workers, seconds in elapsed.items()])
    bench.figure("library job speed-up, 2 workers over 1", elapsed[1] / elapsed[2], "x", "2 cores")


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("species", nargs="*", help=f"presets (default: {', '.join(DEFAULT_SPECIES)})")
    parser.add_argument("--no-scaling", action="store_true", help="skip the 1 and 2 worker job")
    parser.add_argument("--no-twig-cards", action="store_true", help="the spec's twig_cards: false")
    args = parser.parse_args()
    names = args.species or list(DEFAULT_SPECIES)
    twig_cards = not args.no_twig_cards
    bench = Benchmark("library" if twig_cards else "library_no_twig_cards",
                      "Library assets: seconds per asset on one core, levels and sizes", args)
    spec = parse_library_spec({"species": {n: 1 for n in names}, "formats": ["glb", "usd", "obj", "collision"],
                               "texture_size": 256, "impostor_tile": 128, "twig_cards": twig_cards})
    renderer = CoverageRenderer(64)
    stages, records, floors = [], [], {}
    with tempfile.TemporaryDirectory() as tmp:
        location = Location.resolve(tmp)
        # A worker pays its imports (pxr's above all) and GL set-up once, on its first asset: time that asset
        # apart.
        timer = StageTimer()
        write_asset_files(build_asset(WARM_UP, tree_seed(1, 0), spec, renderer, timer), location, spec, renderer,
                          timer)
        bench.note(f"first asset of the process ({WARM_UP}, imports included): {sum(timer.seconds.values()):.2f} s")
        for i, name in enumerate(names):
            timer = StageTimer()
            asset = build_asset(name, tree_seed(0, i), spec, renderer, timer)
            record = write_asset_files(asset, location, spec, renderer, timer)
            stages.append(timer.seconds)
            records.append((name, record))
            floors[name] = {f.level: f for f in asset_floors(asset, renderer)}  # after the timing: extra renders
    stage_table(bench, names, stages)
    level_table(bench, records, floors)
    glb_tables(bench, names, records, spec, renderer, twig_cards)
    if not args.no_scaling:
        scaling(bench)
    bench.write()


if __name__ == "__main__":
    main()
