"""How close any level of detail can come to the IoU target at its switch size: per preset and level, the
library's least silhouette IoU beside two floors of the measure itself, LOD0 against LOD0 seen half a pixel
to the side and LOD0 against LOD0 turned by 1 deg.

- Half a pixel: a LOD whose every vertex stayed within half a pixel of LOD0's (finer than any simplification
  a screen tolerance allows) still moves thin outlines by that much (the least of a move across and a move
  up). Where LOD0 moved by half a pixel falls below the target, the measure cannot tell a LOD accurate to half
  a pixel from a poor one.
- 1 and 4 deg: a view-sampled impostor (crossed planes, a ring of billboards, an octahedral atlas) shows from
  between its views a tree turned by up to half their spacing. LOD0 turned 1 deg is what a billboard with a
  view every 2 deg (180 frames around the tree) shows at worst, before any texel is lost; 4 deg, one with a
  view every 8 deg (45 frames), still far more than the 16 triangles allowed an impostor can show.

Figures: least IoU over renderers.silhouette_metric.QUALITY_AZIMUTHS, both silhouettes closed as the library measures
them, each level at its default switch size; assets built as `farm library` builds them (default spec).

Run: PYOPENGL_PLATFORM=egl python -m benchmarks.bench_silhouette_floor [SPECIES ...] [--no-twig-cards]
(default: every preset, seed tree_seed(0, 0); --no-twig-cards: the spec's `twig_cards: false`, levels of tubes and
leaf cards only)
Reference: the target IoU >= 0.9 at every switch (LOD1 512 px, LOD2 256, LOD3 128, impostor 64).
"""
from __future__ import annotations

import os

import numpy as np

import species
from benchmarks.harness import Benchmark, arguments
from farm.library.quality import FLOOR_MARGIN, SHIFT_PX, level_floors

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

TURNS_DEG = (1.0, 4.0)
COLUMNS = ("library", f"LOD0 {SHIFT_PX:g} px aside", *(f"LOD0 turned {t:g} deg" for t in TURNS_DEG))


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("species", nargs="*", help="presets (default: every preset)")
    parser.add_argument("--no-twig-cards", action="store_true", help="the spec's twig_cards: false")
    args = parser.parse_args()
    names = args.species or [preset.name for preset in species.list_presets()]
    twig_cards = not args.no_twig_cards
    bench = Benchmark("silhouette_floor" if twig_cards else "silhouette_floor_no_twig_cards",
                      "Each level's least IoU beside what the measure itself allows", args)
    from tqdm import tqdm

    from farm.library.asset import build_asset, leaf_fractions
    from farm.library.catalog import IOU_TARGET
    from farm.library.spec import parse_library_spec
    from farm.tree_chain import tree_seed
    from species.timing import StageTimer
    from renderers.alpha_coverage import coverage_tree
    from renderers.framing import framing_points
    from renderers.gl_coverage import CoverageRenderer

    renderer = CoverageRenderer(64)  # one EGL context for every size: the viewport follows the camera
    rows, seconds = {}, {}
    level_names = switch_sizes = None
    for name in tqdm(names, desc="presets", unit="tree"):
        spec = parse_library_spec({"species": {name: 1}, "twig_cards": twig_cards})
        timer = StageTimer()
        asset = build_asset(name, tree_seed(0, 0), spec, renderer, timer)
        seconds[name] = timer.seconds
        lod0_fraction, _ = leaf_fractions(asset.leaf_atlases["summer"])
        cover = coverage_tree(asset.lod0, lod0_fraction)
        points = framing_points(asset.lod0)
        levels = asset.levels[1:]
        level_names = [level.name for level in levels]
        switch_sizes = [level.switch_px for level in levels]
        rows[name] = [(min(level.iou), *level_floors(renderer, cover, points, level.switch_px, TURNS_DEG))
                      for level in levels]

    for k, (level_name, switch_px) in enumerate(zip(level_names, switch_sizes)):
        bench.table(f"{level_name} at {switch_px} px: least silhouette IoU over 8 azimuths (target {IOU_TARGET})",
                    ["preset", *COLUMNS, "margin to 0.5 px", "target"],
                    [(name, *(f"{v:.3f}" for v in levels[k]), f"{levels[k][0] - levels[k][1]:+.3f}",
                      "meets" if levels[k][0] - levels[k][1] >= -FLOOR_MARGIN else "misses")
                     for name, levels in rows.items()])
    summary = []
    for k, level_name in enumerate(level_names):
        table = np.array([levels[k] for levels in rows.values()])
        within = int((table[:, 0] >= table[:, 1] - 0.02).sum())
        counts = (table >= IOU_TARGET).sum(axis=0)
        summary.append([level_name, *(f"{m:.3f}" for m in table.mean(axis=0)), *(int(c) for c in counts), within])
    bench.table(f"Summary over {len(rows)} presets (target {IOU_TARGET})",
                ["level", "mean library", "mean 0.5 px", *(f"mean {t:g} deg" for t in TURNS_DEG), "library >= .9",
                 "0.5 px >= .9", *(f"{t:g} deg >= .9" for t in TURNS_DEG), "within .02"], summary,
                notes=["within .02: presets whose library IoU is at least the half-pixel floor - 0.02"])
    stage_seconds(bench, seconds)
    bench.write()


def stage_seconds(bench: Benchmark, seconds: dict[str, dict[str, float]]) -> None:
    """Seconds of each build stage per preset (one process, warm after the first), and their medians."""
    keys = list(dict.fromkeys(k for sec in seconds.values() for k in sec))
    rows = [(name, *[sec.get(k, 0.0) for k in keys], sum(sec.values())) for name, sec in seconds.items()]
    rows.append(("median", *[float(np.median([s.get(k, 0.0) for s in seconds.values()])) for k in keys],
                 float(np.median([sum(s.values()) for s in seconds.values()]))))
    bench.table("Seconds per stage of `build_asset` (files not written)", ["preset", *keys, "total"], rows)


if __name__ == "__main__":
    main()
