"""The Weber-Penn size estimate against what grows: per tree, the real stems of its largest level, stem nodes and
leaves beside the estimate, their ratios, and the estimate's time; with --memory, the peak memory and seconds of
growing and meshing the largest variants (each in its own process).

Trees: every Weber-Penn preset at a few seeds, TreeSketchNet's dictionaries, and split-heavy and leaf-heavy
variants (black_oak with segSplits[1] = 1.5, pine with 10,000 leaves among them). --before FILE adds the estimate of
another size_estimate.py (say, the last commit's).
Run: python -m benchmarks.bench_size_estimate [--seeds 3] [--before FILE] [--memory]
"""
from __future__ import annotations

from benchmarks.harness import ROOT, Benchmark, arguments, pin_threads

pin_threads()

import argparse  # noqa: E402
import contextlib  # noqa: E402
import importlib.util  # noqa: E402
import json  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import species  # noqa: E402
from fixtures.sapling import TSN_DICTS  # noqa: E402
from species.weber_penn import generator, size_estimate  # noqa: E402
from species.weber_penn.params import WeberPennParams  # noqa: E402

# name: (preset, changes to its sample); split-heavy first, then leaf-heavy.
VARIANTS = {
    "black_oak segSplits[1]=1.5": ("black_oak", {"segSplits": {1: 1.5}}),
    "black_oak segSplits[2]=1.5": ("black_oak", {"segSplits": {2: 1.5}}),
    "black_oak baseSplits=8": ("black_oak", {"baseSplits": 8}),
    "sassafras segSplits .6 all": ("sassafras", {"segSplits": {0: 0.6, 1: 0.6, 2: 0.6}}),
    "maple segSplits[1]=1, baseSplits=6": ("maple", {"segSplits": {1: 1.0}, "baseSplits": 6}),
    "cherry segSplits 1 above": ("cherry", {"segSplits": {1: 1.0, 2: 1.0, 3: 1.0}}),
    "bonsai segSplits[2]=1.5": ("bonsai", {"segSplits": {2: 1.5}}),
    "pine leaves=10000": ("pine", {"leaves": 10000}),
    "balsam_fir leaves=3000": ("balsam_fir", {"leaves": 3000}),
    "quaking_aspen leaves=2000": ("quaking_aspen", {"leaves": 2000}),
    "cherry leaves=-60": ("cherry", {"leaves": -60}),
}


def variant(name: str, seed: int) -> dict:
    """The sample of the variant's preset at `seed` with its changes applied."""
    preset, changes = VARIANTS[name]
    params = species.sample(preset, np.random.default_rng(seed))
    for key, change in changes.items():
        if isinstance(change, dict):
            params[key] = [change.get(level, value) for level, value in enumerate(params[key])]
        else:
            params[key] = change
    return params


def trees(seeds: int) -> list[tuple[str, dict]]:
    out = [(path.stem, json.loads(path.read_text())) for path in sorted(TSN_DICTS.glob("*.json"))]
    presets = [preset.name for preset in species.list_presets() if preset.generator == "weber_penn"]
    out += [(f"{name} s{seed}", species.sample(name, np.random.default_rng(seed)))
            for name in presets for seed in range(seeds)]
    out += [(f"{name} s{seed}", variant(name, seed)) for name in VARIANTS for seed in range(seeds)]
    return out


@contextlib.contextmanager
def no_limits():
    """Grow whatever the estimate says, to count what really grows."""
    names = ("MAX_ESTIMATED_STEMS_PER_LEVEL", "MAX_ESTIMATED_NODES", "MAX_ESTIMATED_LEAVES")
    saved = {name: getattr(size_estimate, name) for name in names}
    for name in names:
        setattr(size_estimate, name, float("inf"))
    try:
        yield
    finally:
        for name, value in saved.items():
            setattr(size_estimate, name, value)


def real_counts(params: dict) -> tuple[list[int], int, int]:
    """Splines per level, dense stem nodes and leaves of the grown tree."""
    rng = species.rng_for(params)
    with no_limits():
        tree = generator.grow_tree(WeberPennParams.from_dict(params, rng), rng)
    splines = [level.n_splines for level in tree.levels]
    nodes = sum(level.n_splines * (level.n_segments + 1) for level in tree.levels)
    return splines, nodes, len(tree.leaves)


def estimated(module, params: dict) -> tuple[list[float], float, float, bool, float]:
    """Splines per level, nodes, leaves, whether refused, and seconds, from `module`'s estimate."""
    read = WeberPennParams.from_dict(params, np.random.default_rng(0))
    started = time.perf_counter()
    estimate = module.estimate_size(read)
    seconds = time.perf_counter() - started
    try:
        module.check_tree_size(read)
        refused = False
    except species.TreeTooLargeError:
        refused = True
    return list(estimate.splines), estimate.total_nodes, estimate.leaves, refused, seconds


def load(path: str):
    """Another version of size_estimate.py (as `git show HEAD:species/weber_penn/size_estimate.py` writes it),
    imported inside species.weber_penn so its relative imports resolve."""
    name = "species.weber_penn.size_estimate_before"
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def _cell(estimate: tuple, real_level: int, real_nodes: int, real_leaves: int, level: int) -> list:
    splines, nodes, leaves, refused, _ = estimate
    ratio = [splines[level] / max(real_level, 1), nodes / max(real_nodes, 1), leaves / max(real_leaves, 1)]
    return [f"{splines[level]:,.0f}", f"{nodes:,.0f}", f"{leaves:,.0f}", "/".join(f"{r:.2f}" for r in ratio),
            "REFUSED" if refused else ""]


def measure_one(name: str, seed: int) -> None:
    """Grow and mesh one variant in this process; print seconds and peak memory as JSON."""
    params = variant(name, seed)
    started = time.perf_counter()
    with no_limits():
        skeleton = species.grow(params, species.rng_for(params))
        mesh = species.build_mesh(skeleton, params)
    seconds = time.perf_counter() - started
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(json.dumps({"seconds": seconds, "peak_mib": peak, "leaves": int(len(skeleton.leaves)),
                      "nodes": int(skeleton.n_nodes), "bark_faces": int(len(mesh.bark.faces))}))


def memory_table(bench: Benchmark, seeds: int) -> None:
    rows = []
    for name in ("black_oak segSplits[1]=1.5", "pine leaves=10000", "balsam_fir leaves=3000"):
        for seed in range(seeds):
            out = subprocess.run([sys.executable, "-m", "benchmarks.bench_size_estimate", "--one", name, str(seed)],
                                 cwd=ROOT, check=True, capture_output=True, text=True).stdout
            figures = json.loads(out.strip().splitlines()[-1])
            rows.append((f"{name} s{seed}", f"{figures['leaves']:,}", f"{figures['nodes']:,}",
                         f"{figures['bark_faces']:,}", f"{figures['seconds']:.1f}", f"{figures['peak_mib']:,.0f}"))
    bench.table("the largest variants grown and meshed, each in a process of its own",
                ["tree", "leaves", "skeleton nodes", "bark faces", "grow+mesh s", "peak MiB"], rows)


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--before", help="another size_estimate.py to compare with")
    parser.add_argument("--memory", action="store_true", help="also grow and mesh the largest variants")
    parser.add_argument("--one", nargs=2, metavar=("VARIANT", "SEED"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        measure_one(args.one[0], int(args.one[1]))
        return
    bench = Benchmark("size_estimate", "The Weber-Penn size estimate against what grows", args)
    before = load(args.before) if args.before else None
    header = ["tree", "real splines (largest level)", "nodes", "leaves"]
    if before:
        header += ["before: splines", "nodes", "leaves", "ratios s/n/l", ""]
    header += ["after: splines", "nodes", "leaves", "ratios s/n/l", "", "ms"]
    rows, worst, least, seconds = [], [0.0, 0.0, 0.0], [np.inf] * 3, []
    for name, params in trees(args.seeds):
        splines, nodes, leaves = real_counts(params)
        level = int(np.argmax(splines))
        after = estimated(size_estimate, params)
        row = [name, f"{splines[level]:,}", f"{nodes:,}", f"{leaves:,}"]
        if before:
            row += _cell(estimated(before, params), splines[level], nodes, leaves, level)
        row += _cell(after, splines[level], nodes, leaves, level) + [f"{after[4] * 1000:.1f}"]
        ratios = [after[0][level] / max(splines[level], 1), after[1] / max(nodes, 1),
                  (after[2] / leaves) if leaves else 1.0]
        worst = [max(w, r) for w, r in zip(worst, ratios)]
        least = [min(m, r) for m, r in zip(least, ratios)]
        seconds.append(after[4])
        rows.append(row)
    bench.table("estimate against the grown tree, per tree", header, rows,
                notes=[f"ratio estimate/real splines {least[0]:.2f}-{worst[0]:.2f}, nodes {least[1]:.2f}-"
                       f"{worst[1]:.2f}, leaves {least[2]:.2f}-{worst[2]:.2f}; estimate {1000 * max(seconds):.1f} ms "
                       "at most"])
    if args.memory:
        memory_table(bench, 1)
    bench.write()


if __name__ == "__main__":
    main()
