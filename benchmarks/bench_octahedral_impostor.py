"""The octahedral impostor beside the crossed planes, per preset: least and mean silhouette IoU against LOD0 at the
impostor's switch size (64 px), from renderers.silhouette_metric.QUALITY_AZIMUTHS (halfway between the crossed
planes) and from the azimuths halfway between the octahedral atlas's horizon frames (its worst case at the horizon),
measured as the library measures them (`farm.library.asset.measure_chain`: closed silhouettes, LOD0's cards cut to
their opaque share); seconds to render each atlas and its PNG bytes (albedo + normal, the library's encoding).

Run: PYOPENGL_PLATFORM=egl python -m benchmarks.bench_octahedral_impostor [SPECIES ...] [--all]
     [--frames N]   (default: DEFAULT_PRESETS; --all: every preset; N frames per side, default 12)
The figures are in docs/library.md ("Octahedral impostor").
"""
from __future__ import annotations


import numpy as np
from tqdm import tqdm

import species
from benchmarks.harness import Benchmark, arguments, time_case
from farm.library.asset import build_asset, leaf_fractions
from farm.library.catalog import IOU_TARGET
from farm.library.png_cache import PngCache
from farm.library.spec import DEFAULT_IMPOSTOR_TILE, parse_library_spec
from farm.tree_chain import tree_seed
from renderers.alpha_coverage import coverage_tree
from renderers.framing import framing_points
from renderers.gl_coverage import CoverageRenderer
from renderers.impostor import render_impostor
from renderers.silhouette_metric import QUALITY_AZIMUTHS, closed_silhouette, silhouette_iou, switch_camera
from renderers.octahedral_impostor import OCTAHEDRAL_FRAMES, between_frame_azimuths, render_octahedral_impostor
from species.timing import StageTimer

DEFAULT_PRESETS = ("maple", "pine", "palm", "balsam_fir", "sc_young_sapling")
KINDS = ("crossed", "octahedral")


def measure(renderer, cover, points, atlas, azimuths, switch_px: int) -> tuple[float, float]:
    """(least, mean) IoU of the atlas's silhouette against LOD0's coverage tree from `azimuths`."""
    ious = []
    for azimuth in azimuths:
        camera = switch_camera(points, azimuth, switch_px)
        reference = closed_silhouette(renderer.coverage(cover, camera))
        ious.append(silhouette_iou(reference, closed_silhouette(atlas.coverage(camera))))
    return min(ious), float(np.mean(ious))


def preset_row(renderer, name: str, frames: int, pngs: PngCache) -> dict:
    """Both impostors of the preset's tree_seed(0, 0) asset (the library's default spec otherwise)."""
    spec = parse_library_spec({"species": {name: 1}, "impostor": "octahedral", "impostor_frames": frames})
    asset = build_asset(name, tree_seed(0, 0), spec, renderer, StageTimer())
    cover = coverage_tree(asset.lod0, leaf_fractions(asset.leaf_atlases["summer"])[0])
    points = framing_points(asset.lod0)
    switch_px = asset.levels[-1].switch_px
    between = between_frame_azimuths(frames)
    renders = {"crossed": lambda: render_impostor(renderer, cover, tile=DEFAULT_IMPOSTOR_TILE),
               "octahedral": lambda: render_octahedral_impostor(renderer, cover, frames, spec.impostor_tile)}
    row = {}
    for kind, render in renders.items():
        rendered = time_case(render, 1)
        atlas, seconds = rendered.result, rendered.median
        row[kind] = (*measure(renderer, cover, points, atlas, QUALITY_AZIMUTHS, switch_px),
                     *measure(renderer, cover, points, atlas, between, switch_px), seconds,
                     len(pngs.encode(atlas.albedo)) + len(pngs.encode(atlas.normal)))
    # The library's own figure for the asset's (octahedral) impostor is the first column's.
    assert abs(row["octahedral"][0] - min(asset.levels[-1].iou)) < 1e-9
    return row


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("species", nargs="*", help=f"presets (default: {', '.join(DEFAULT_PRESETS)})")
    parser.add_argument("--all", action="store_true", help="every preset")
    parser.add_argument("--frames", type=int, default=OCTAHEDRAL_FRAMES, help="octahedral frames per side")
    args = parser.parse_args()
    names = [p.name for p in species.list_presets()] if args.all else args.species or list(DEFAULT_PRESETS)
    bench = Benchmark("octahedral_impostor", "The octahedral impostor beside the crossed planes", args)
    renderer, pngs = CoverageRenderer(64), PngCache()
    try:
        rows = {name: preset_row(renderer, name, args.frames, pngs) for name in tqdm(names, unit="preset")}
    finally:
        renderer.close()
    columns = [f"{kind} {column}" for kind in KINDS for column in ("q min", "q avg", "b min", "b avg", "s", "KB")]
    table = np.array([[v for kind in KINDS for v in row[kind]] for row in rows.values()])
    cells = [[f"{v:.3f}" if k % 6 < 4 else f"{v:.2f}" if k % 6 == 4 else f"{v / 1024:.0f}" for k, v in enumerate(values)]
             for values in [*table, table.mean(axis=0)]]
    at_target = ["" if k % 6 >= 4 else int(c) for k, c in enumerate((table >= IOU_TARGET).sum(axis=0))]
    bench.table(f"impostor IoU against LOD0 at 64 px (target {IOU_TARGET}), least / mean over the 8 quality azimuths "
                f"(q) and the {len(between_frame_azimuths(args.frames))} azimuths between the {args.frames} x "
                f"{args.frames} atlas's horizon frames (b); seconds to render; atlas PNG KB",
                ["preset", *columns],
                [[name, *row] for name, row in zip([*rows, "mean"], cells)] + [["at the target", *at_target]])
    bench.write()


if __name__ == "__main__":
    main()
