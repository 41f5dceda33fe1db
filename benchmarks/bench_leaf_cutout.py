"""Leaf cards against cut-out leaf geometry (the library spec's `leaves: cards | cutout`): triangles per level, file
sizes (GLB with instanced leaves, GLB baked as Blender and FBX take it, USD), the seconds the cutout adds to an
asset, and the Cycles render time of the same view of LOD0 (the baked GLB, leaves alpha-tested cards or opaque
outline polygons; CPU, one thread, 256 px, 16 samples, every render after the first of its file).

Seeds are tree_seed(0, position in the list), as bench_library's: compare figures only between runs of one list.
Run: PYOPENGL_PLATFORM=egl python -m benchmarks.bench_leaf_cutout [SPECIES ...] [--no-render]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads

pin_threads(one_core=True)

import json  # noqa: E402
import os  # noqa: E402
import struct  # noqa: E402

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

from farm.library.asset import build_asset  # noqa: E402
from farm.library.gltf_asset import asset_to_glb  # noqa: E402
from farm.library.spec import parse_library_spec  # noqa: E402
from farm.library.usd_asset import asset_to_usdc  # noqa: E402
from farm.tree_chain import tree_seed  # noqa: E402
from renderers.blender import blender_available, time_cycles_view  # noqa: E402
from renderers.camera import perspective_camera  # noqa: E402
from renderers.framing import framing_points  # noqa: E402
from renderers.gl_coverage import CoverageRenderer  # noqa: E402
from species.meshing.gltf import read_glb_chunks  # noqa: E402
from species.timing import StageTimer  # noqa: E402

DEFAULT_SPECIES = ("sc_young_sapling", "palm", "maple", "sassafras")
KINDS = ("cards", "cutout")
RENDER_SIZE, SAMPLES, VIEWS = 256, 16, 3  # the first view of each file builds Cycles' BVH: the mean is of all 3


def without_wind(glb: bytes) -> bytes:
    """The GLB without its `_WIND`/`_WIND_PIVOT` attributes (their accessors stay, unused): the photo worker imports
    with Blender's own glTF importer, which pairs two custom attributes of different widths by a set's order."""
    document, binary = read_glb_chunks(glb)
    for mesh in document["meshes"]:
        for primitive in mesh["primitives"]:
            for name in ("_WIND", "_WIND_PIVOT"):
                primitive["attributes"].pop(name, None)
    text = json.dumps(document, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<I4s", len(text), b"JSON") + text + struct.pack("<I4s", len(binary), b"BIN\0") + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def measure(name: str, index: int, renderer, render: bool) -> dict[str, dict]:
    """{kind: figures} of one species' asset built with leaf cards and with cut-out leaves."""
    out = {}
    for kind in KINDS:
        spec = parse_library_spec({"species": {name: 1}, "leaves": kind, "formats": ["glb", "usd"]})
        timer = StageTimer()
        asset = build_asset(name, tree_seed(0, index), spec, renderer, timer)
        flat = asset_to_glb(asset, instanced=False)
        figures = {"triangles": [level.n_triangles for level in asset.levels],
                   "glb": len(asset_to_glb(asset)), "glb_baked": len(flat), "usd": len(asset_to_usdc(asset)),
                   "cutout_s": timer.seconds.get("cutout", 0.0),
                   "outline_triangles": asset.leaf_outline.n_triangles if asset.leaf_outline else 2}
        if render:
            camera = perspective_camera(framing_points(asset.lod0), 30.0, 10.0, RENDER_SIZE)
            figures["render_s"] = time_cycles_view(RENDER_SIZE, without_wind(flat), [camera] * VIEWS,
                                                   samples=SAMPLES, threads=1)
        out[kind] = figures
    return out


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("species", nargs="*", help=f"presets (default: {', '.join(DEFAULT_SPECIES)})")
    parser.add_argument("--no-render", action="store_true", help="skip the Cycles render times")
    args = parser.parse_args()
    names = args.species or list(DEFAULT_SPECIES)
    render = not args.no_render and blender_available()
    bench = Benchmark("leaf_cutout", "Leaf cards against cut-out leaf geometry: triangles, bytes, render time", args)
    renderer = CoverageRenderer(64)
    rows, levels = [], []
    for i, name in enumerate(names):
        figures = measure(name, i, renderer, render)
        cards, cutout = figures["cards"], figures["cutout"]
        for kind in KINDS:
            f = figures[kind]
            rows.append((name, kind, f["triangles"][0], f["glb"], f["glb_baked"], f["usd"],
                         f"{f['render_s']:.2f}" if render else "", f"{f['cutout_s'] * 1000:.1f}"))
        rows.append((name, "cutout / cards", f"{cutout['triangles'][0] / cards['triangles'][0]:.2f}x",
                     f"{cutout['glb'] / cards['glb']:.3f}x", f"{cutout['glb_baked'] / cards['glb_baked']:.2f}x",
                     f"{cutout['usd'] / cards['usd']:.3f}x",
                     f"{cutout['render_s'] / cards['render_s']:.2f}x" if render else "", ""))
        levels.append((name, " / ".join(str(t) for t in cards["triangles"]),
                       " / ".join(str(t) for t in cutout["triangles"]), cutout["outline_triangles"]))
    bench.table("LOD0 of each asset, leaf cards against cut-out leaves",
                ["species", "leaves", "LOD0 triangles", "GLB bytes", "baked GLB bytes", "USD bytes",
                 "Cycles s / view", "cutout ms"], rows,
                notes=[f"Cycles: CPU, one thread, {RENDER_SIZE} px, {SAMPLES} samples, the baked GLB's LOD0 from "
                       f"azimuth 30, elevation 10 (cards cut by their alpha, outline polygons opaque)",
                       "cutout ms: tracing the outline and placing it, per asset"])
    bench.table("triangles per level (LOD0 / LOD1 / LOD2 / LOD3 / impostor)",
                ["species", "cards", "cutout", "triangles per outline"], levels,
                notes=["clump cards (coarser levels) stay two-triangle cards with an alpha test"])
    renderer.close()
    bench.write()


if __name__ == "__main__":
    main()
