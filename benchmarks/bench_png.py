"""PNG encoding time and size by zlib level on the library's textures: what `farm.library.png_cache`'s level 2
costs and saves against the species encoder's default 9 (`species.meshing.png.png_bytes`).

Images: one species' bark maps (base colour, normal, roughness/metallic) at the library's default texture size
and its leaf atlases of the three leafy seasons, the textures every asset's GLB and USD embed or reference.
Prints median ms per image set and total bytes per level, and each level against level 9.
Run: python -m benchmarks.bench_png [--species maple] [--texture-size 256] [--repeats 5]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads, time_case

pin_threads()

import numpy as np  # noqa: E402

import species  # noqa: E402
from species.meshing.png import png_bytes  # noqa: E402
from species.studio.pbr_textures import SEASONS, bark_maps, leaf_atlas, season_leaf_colour  # noqa: E402

LEVELS = (1, 2, 3, 6, 9)


def library_textures(species_name: str, size: int) -> list[np.ndarray]:
    """The bark maps and leafy-season leaf atlases one asset of `species_name` carries, as the library makes them."""
    params = species.sample(species_name, np.random.default_rng(0))
    _, mesh = species.rebuild(params)
    maps = bark_maps(species_name, mesh.bark_color, size)
    atlases = [leaf_atlas(season_leaf_colour(s, mesh.leaf_color), size // 2) for s in SEASONS if s != "bare"]
    return [maps.base_color, maps.normal, maps.roughness_metallic, *atlases]


def main() -> None:
    parser = arguments(__doc__, repeats=5)
    parser.add_argument("--species", default="maple")
    parser.add_argument("--texture-size", type=int, default=256)
    args = parser.parse_args()
    bench = Benchmark("png", "PNG encoding of the library's textures by zlib level", args)
    images = library_textures(args.species, args.texture_size)
    levels = {level: time_case(lambda: sum(len(png_bytes(image, level)) for image in images), args.repeats)
              for level in LEVELS}
    slowest, smallest = levels[9].median, levels[9].result
    bench.table(f"{args.species}, texture size {args.texture_size}: {len(images)} images, "
                f"{sum(image.nbytes for image in images)} bytes of pixels",
                ["level", "ms", "bytes", "speed vs 9", "size vs 9"],
                [(level, timing, timing.result, f"{slowest / timing.median:.1f}x", f"{timing.result / smallest:.2f}x")
                 for level, timing in levels.items()])
    bench.write()


if __name__ == "__main__":
    main()
