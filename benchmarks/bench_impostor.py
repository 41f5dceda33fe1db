"""The impostor's slicing and alpha settings side by side: least silhouette IoU against LOD0 at the impostor's
switch size (64 px) over renderers.impostor.QUALITY_AZIMUTHS, per preset, for each (axis share, sector overlap,
alpha grown by N texels) variant, measured as the library measures it (`farm.library.asset.measure_chain`).

The library's settings are renderers.impostor.AXIS_SHARE and SECTOR_OVERLAP, with the alpha not grown.
Measured on the 45 presets (tree_seed(0, 0), least IoU at 64 px over the quality azimuths), mean: .718 with axis
share 0.04 and no overlap, .737 with 0.2 and none, .745 with 0.2 and 0.15 (presets at >= 0.9: 6 -> 10); an
overlap of 0.3 or 0.5 (every face on two planes) smears, .746 and .740. Alpha grown by one texel, then not grown
(before slicing): maple .855 -> .894, balsam_fir .275 -> .414, douglas_fir .477 -> .545, cherry .752 -> .808 (at
the impostor's switch size a texel is about a screen pixel, and a sparse crown grown by one each way goes far
beyond its closed silhouette).

Run: PYOPENGL_PLATFORM=egl .venv/bin/python benchmarks/bench_impostor.py [SPECIES ...]  (default: every preset;
about 1 s per preset and variant on one core)
"""
from __future__ import annotations

import os
import sys

import numpy as np

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

# (axis share, sector overlap, alpha grown by texels): the library's, then the alternatives measured above.
VARIANTS = ((0.2, 0.15, 0), (0.04, 0.0, 0), (0.2, 0.0, 0), (0.2, 0.3, 0), (0.2, 0.15, 1))


def least_iou(renderer, asset, cover, variant) -> float:
    from renderers.alpha_coverage import triangle_coverage
    from renderers.framing import framing_points
    from renderers.impostor import (QUALITY_AZIMUTHS, closed_silhouette, render_impostor, silhouette_iou,
                                    switch_camera)

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


def main(names: list[str]) -> None:
    from tqdm import tqdm

    from farm.library.asset import build_asset, leaf_fractions
    from farm.library.catalog import IOU_TARGET
    from farm.library.spec import parse_library_spec
    from farm.tree_chain import tree_seed
    from species.timing import StageTimer
    from renderers.alpha_coverage import coverage_tree
    from renderers.impostor import CoverageRenderer

    renderer = CoverageRenderer(64)
    rows = {}
    for name in tqdm(names, desc="presets", unit="tree"):
        asset = build_asset(name, tree_seed(0, 0), parse_library_spec({"species": {name: 1}}), renderer,
                            StageTimer())
        cover = coverage_tree(asset.lod0, leaf_fractions(asset.leaf_atlases["summer"])[0])
        rows[name] = [least_iou(renderer, asset, cover, variant) for variant in VARIANTS]
    renderer.close()
    heads = [f"axis {a:g} overlap {o:g} grow {t}" for a, o, t in VARIANTS]
    print(f"\nimpostor least IoU at its switch size (target {IOU_TARGET}); first column: the library's settings")
    print(f"{'preset':28s} | " + " | ".join(f"{h:>24s}" for h in heads))
    for name, values in rows.items():
        print(f"{name:28s} | " + " | ".join(f"{v:24.3f}" for v in values))
    table = np.array(list(rows.values()))
    print(f"{'mean':28s} | " + " | ".join(f"{v:24.3f}" for v in table.mean(axis=0)))
    print(f"{'presets at the target':28s} | " + " | ".join(f"{int(c):24d}" for c in (table >= IOU_TARGET).sum(axis=0)))


if __name__ == "__main__":
    import species

    main(sys.argv[1:] or [preset.name for preset in species.list_presets()])
