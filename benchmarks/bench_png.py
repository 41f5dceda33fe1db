"""PNG encoding time and size by zlib level on the library's textures: what `farm.library.png_cache`'s level 2
costs and saves against the species encoder's default 9 (`species.meshing.png.png_bytes`).

Images: one species' bark maps (base colour, normal, roughness/metallic) at the library's default texture size
and its leaf atlases of the three leafy seasons, the textures every asset's GLB and USD embed or reference.
Prints median ms per image set and total bytes per level, and each level against level 9.
Run: .venv/bin/python benchmarks/bench_png.py [--species maple] [--texture-size 256] [--repeats 5]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from species.meshing.png import png_bytes
from species.studio.pbr_textures import SEASONS, bark_maps, leaf_atlas, season_leaf_colour

LEVELS = (1, 2, 3, 6, 9)


def library_textures(species_name: str, size: int) -> list[np.ndarray]:
    """The bark maps and leafy-season leaf atlases one asset of `species_name` carries, as the library makes them."""
    import species

    params = species.sample(species_name, np.random.default_rng(0))
    _, mesh = species.rebuild(params)
    maps = bark_maps(species_name, mesh.bark_color, size)
    atlases = [leaf_atlas(season_leaf_colour(s, mesh.leaf_color), size // 2) for s in SEASONS if s != "bare"]
    return [maps.base_color, maps.normal, maps.roughness_metallic, *atlases]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--species", default="maple")
    parser.add_argument("--texture-size", type=int, default=256)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    images = library_textures(args.species, args.texture_size)
    rows = {}
    for level in LEVELS:
        times = []
        for _ in range(args.repeats):
            start = time.perf_counter()
            size = sum(len(png_bytes(image, level)) for image in images)
            times.append(time.perf_counter() - start)
        rows[level] = (1000.0 * float(np.median(times)), size)
    slow_ms, small_bytes = rows[9]
    print(f"{args.species}, texture size {args.texture_size}: {len(images)} images, "
          f"{sum(image.nbytes for image in images)} bytes of pixels")
    print(f"{'level':>5} | {'ms':>8} | {'bytes':>9} | {'speed vs 9':>10} | {'size vs 9':>9}")
    for level, (ms, size) in rows.items():
        print(f"{level:>5} | {ms:8.1f} | {size:9d} | {slow_ms / ms:9.1f}x | {size / small_bytes:8.2f}x")


if __name__ == "__main__":
    main()
