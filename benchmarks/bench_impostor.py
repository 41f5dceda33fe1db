"""The impostor's slicing and alpha settings side by side: least silhouette IoU against LOD0 at the impostor's
switch size (64 px) over renderers.silhouette_metric.QUALITY_AZIMUTHS, per preset, for each (axis share, sector overlap,
alpha grown by N texels) variant, measured as the library measures it (`farm.library.asset.measure_chain`).

The library's settings are renderers.impostor.AXIS_SHARE and SECTOR_OVERLAP, with the alpha not grown; the first
column. docs/library.md ("Impostor") says what the alternatives give.

Run: PYOPENGL_PLATFORM=egl python -m benchmarks.bench_impostor [SPECIES ...]  (default: every preset)
"""
from __future__ import annotations

import os

import numpy as np

import species
from benchmarks.harness import Benchmark, arguments

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

# (axis share, sector overlap, alpha grown by texels): the library's, then the alternatives.
VARIANTS = ((0.2, 0.15, 0), (0.04, 0.0, 0), (0.2, 0.0, 0), (0.2, 0.3, 0), (0.2, 0.15, 1))


def least_iou(renderer, asset, cover, variant) -> float:
    from renderers.alpha_coverage import triangle_coverage
    from renderers.framing import framing_points
    from renderers.impostor import render_impostor
    from renderers.silhouette_metric import QUALITY_AZIMUTHS, closed_silhouette, silhouette_iou, switch_camera

    axis_share, overlap, texels = variant
    atlas = render_impostor(renderer, cover, tile=asset.impostor.tile, axis_share=axis_share,
                            sector_overlap=overlap)
    grown = atlas.grown(texels)  # within each tile, as the library grows it (`lod_fit.fit_impostor`)
    billboard, opaque = grown.mesh(), grown.albedo[..., 3] >= 128
    switch_px = asset.levels[-1].switch_px
    points = framing_points(asset.lod0)
    ious = []
    for azimuth in QUALITY_AZIMUTHS:
        camera = switch_camera(points, azimuth, switch_px)
        reference = closed_silhouette(renderer.coverage(cover, camera))
        drawn = triangle_coverage(camera, billboard.vertices, billboard.faces, billboard.uvs, opaque)
        ious.append(silhouette_iou(reference, closed_silhouette(drawn)))
    return min(ious)


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("species", nargs="*", help="presets (default: every preset)")
    args = parser.parse_args()
    names = args.species or [preset.name for preset in species.list_presets()]
    bench = Benchmark("impostor", "The impostor's slicing and alpha settings side by side", args)
    from tqdm import tqdm

    from farm.library.asset import build_asset, leaf_fractions
    from farm.library.catalog import IOU_TARGET
    from farm.library.spec import parse_library_spec
    from farm.tree_chain import tree_seed
    from species.timing import StageTimer
    from renderers.alpha_coverage import coverage_tree
    from renderers.gl_coverage import CoverageRenderer

    renderer = CoverageRenderer(64)
    rows = {}
    for name in tqdm(names, desc="presets", unit="tree"):
        asset = build_asset(name, tree_seed(0, 0), parse_library_spec({"species": {name: 1}}), renderer,
                            StageTimer())
        cover = coverage_tree(asset.lod0, leaf_fractions(asset.leaf_atlases["summer"])[0])
        rows[name] = [least_iou(renderer, asset, cover, variant) for variant in VARIANTS]
    renderer.close()
    heads = [f"axis {a:g} overlap {o:g} grow {t}" for a, o, t in VARIANTS]
    table = np.array(list(rows.values()))
    bench.table(f"impostor least IoU at its switch size (target {IOU_TARGET}); first column: the library's settings",
                ["preset", *heads],
                [(name, *(f"{v:.3f}" for v in values)) for name, values in rows.items()]
                + [("mean", *(f"{v:.3f}" for v in table.mean(axis=0))),
                   ("presets at the target", *(int(c) for c in (table >= IOU_TARGET).sum(axis=0)))])
    bench.write()


if __name__ == "__main__":
    main()
