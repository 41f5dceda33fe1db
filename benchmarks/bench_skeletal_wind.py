"""What baked skeletal wind costs a library asset: CPU seconds per asset on one core (build and every file but
Blender's; CPU time, so other processes on a shared machine count less) with `skeletal_wind` off (the default)
and on, the GLB and USD bytes with and without it, and the
joints per asset.

Each species is built and written with the clip off then on, `--repeats` times alternating, so both see the same
load; the first asset of the process (imports, GL set-up) is built apart. Seeds are tree_seed(0, position in the
list): compare figures only between runs of the same list.
Reference: the default asset's time target is < 1.5 s median on one core (docs/library.md); skeletal wind off
must not slow it by more than 10 %.
Run: PYOPENGL_PLATFORM=egl python -m benchmarks.bench_skeletal_wind [SPECIES ...] [--repeats N]
"""
from __future__ import annotations

from benchmarks.harness import Benchmark, arguments, pin_threads

pin_threads(one_core=True)

import os  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

os.environ.setdefault("PYOPENGL_PLATFORM", "egl")

import numpy as np  # noqa: E402

from farm.dataset.storage import Location  # noqa: E402
from farm.library.asset import build_asset  # noqa: E402
from farm.library.job import write_asset_files  # noqa: E402
from farm.library.spec import parse_library_spec  # noqa: E402
from farm.tree_chain import tree_seed  # noqa: E402
from renderers.gl_coverage import CoverageRenderer  # noqa: E402
from species.timing import StageTimer  # noqa: E402

DEFAULT_SPECIES = ("maple", "pine", "cherry", "palm", "sc_young_sapling", "lsystem_monopodial", "sassafras",
                   "douglas_fir", "balsam_fir")
WARM_UP = "bonsai"


def one_asset(name: str, seed: int, spec, renderer, location) -> tuple[float, dict, object]:
    """CPU seconds to build and write one asset, its record, and the asset."""
    start = time.process_time()
    timer = StageTimer()
    asset = build_asset(name, seed, spec, renderer, timer)
    record = write_asset_files(asset, location, spec, renderer, timer)
    return time.process_time() - start, record, asset


def main() -> None:
    parser = arguments(__doc__, repeats=1)
    parser.add_argument("species", nargs="*", help=f"presets (default: {', '.join(DEFAULT_SPECIES)})")
    args = parser.parse_args()
    names = args.species or list(DEFAULT_SPECIES)
    bench = Benchmark("skeletal_wind", "Skeletal wind: seconds and bytes per asset with the clip off and on", args)
    base = {"species": {n: 1 for n in names}, "formats": ["glb", "usd", "obj", "collision"], "texture_size": 256,
            "impostor_tile": 128}
    specs = {"off": parse_library_spec(base), "on": parse_library_spec({**base, "skeletal_wind": True})}
    renderer = CoverageRenderer(64)
    rows, seconds = [], {"off": [], "on": []}
    with tempfile.TemporaryDirectory() as tmp:
        location = Location.resolve(tmp)
        for spec in specs.values():
            one_asset(WARM_UP, tree_seed(1, 0), spec, renderer, location)
        for i, name in enumerate(names):
            runs = {"off": [], "on": []}
            for _ in range(args.repeats):
                for key, spec in specs.items():
                    elapsed, record, asset = one_asset(name, tree_seed(0, i), spec, renderer, location)
                    runs[key].append(elapsed)
                    if key == "on":
                        on_record, joints = record, asset.wind_rig.n_joints
                    else:
                        off_record = record
            off, on = (float(np.median(runs[k])) for k in ("off", "on"))
            seconds["off"].append(off)
            seconds["on"].append(on)
            sizes = [off_record["sizes"]["glb"], on_record["sizes"]["glb"], off_record["sizes"]["usd"],
                     on_record["sizes"]["usd"]]
            rows.append((name, off, on, f"{100 * (on / off - 1):+.1f} %", on - off, joints, *sizes,
                         f"{100 * (sizes[1] / sizes[0] - 1):+.1f} %", f"{100 * (sizes[3] / sizes[2] - 1):+.1f} %"))
    bench.table("CPU seconds per asset (one core, build and files but Blender's) and bytes, skeletal wind off and on",
                ["species", "off s", "on s", "time", "added s", "joints", "GLB off", "GLB on", "USD off", "USD on", "GLB",
                 "USD"], rows, notes=["joint budget 64 (the default), 6 s clip at 15 keys a second"])
    for key in ("off", "on"):
        bench.figure(f"median CPU seconds per asset, skeletal wind {key}", float(np.median(seconds[key])), "s",
                     "one core; target < 1.5 s")
    bench.figure("median CPU seconds skeletal wind adds to an asset",
                 float(np.median(np.subtract(seconds["on"], seconds["off"]))), "s", "one core")
    bench.write()


if __name__ == "__main__":
    main()
