"""Differential comparison: treefarm's Weber-Penn generator against Blender's Sapling add-on, in distribution.

Each dictionary of `fixtures.sapling` (Sapling's own presets, TreeSketchNet's dictionaries, dictionaries sampled
from our presets as Sapling ranges) is grown over seeds by both; per dictionary it prints median and IQR of bark
height, crown radius, stems per level and leaf count, the treefarm/Sapling ratio of medians with a bootstrap 95 %
interval, worst first, and the speed ratio. The Sapling side is read from fixtures/references/sapling_fidelity.json
unless --rerun-sapling (Blender's venv, `make blender-env`; about 20 minutes).
Run: python -m benchmarks.bench_sapling_fidelity [--seeds 24] [--png out/sapling_fidelity.png]
"""
from __future__ import annotations

from benchmarks.harness import ROOT, Benchmark, arguments, pin_threads

pin_threads()

import json  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from PIL import Image, ImageDraw  # noqa: E402

from fixtures.sapling import (FIDELITY_REFERENCE, N_PRESET_DICTS, N_SEEDS, HarnessDict, compare,  # noqa: E402
                              harness_dictionaries, stale_dictionaries, tolerance, treefarm_figures)

RUNNER = ROOT / "benchmarks" / "sapling_runner.py"
BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"


def grow_treefarm(harness: list[HarnessDict], seeds: int) -> dict[str, list[dict]]:
    """treefarm's rows per dictionary, seeds 0..seeds-1, after one warm-up tree (imports and caches)."""
    treefarm_figures(harness[0].treefarm, 0)
    return {h.name: [{"seed": s, **treefarm_figures(h.treefarm, s)} for s in range(seeds)] for h in harness}


def run_sapling(harness: list[HarnessDict], seeds: int, work: Path) -> dict:
    """Grow every dictionary with Sapling (one Blender process, resumable through work/rows.jsonl); returns the
    reference: versions, the dictionaries Sapling was given and its rows per dictionary."""
    work.mkdir(parents=True, exist_ok=True)
    dicts = {h.name: h.sapling for h in harness}
    (work / "dicts.json").write_text(json.dumps({"dictionaries": dicts}))
    rows_path = work / "rows.jsonl"
    start = time.perf_counter()
    subprocess.run([str(BLENDER_PYTHON), str(RUNNER), str(work / "dicts.json"), "--seeds", str(seeds),
                    "--out", str(rows_path)], check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    versions = json.loads(subprocess.run([str(BLENDER_PYTHON), str(RUNNER), str(work / "dicts.json"), "--versions",
                                          "--out", str(rows_path)], check=True, capture_output=True,
                                         text=True).stdout.strip().splitlines()[-1])
    return reference_from_rows(rows_path, dicts, seeds, versions, wall)


def reference_from_rows(rows_path: Path, dicts: dict[str, dict], seeds: int, versions: dict, wall: float) -> dict:
    """The cache's content from the runner's JSON lines: rows of the harness dictionaries by seed."""
    rows: dict[str, list[dict]] = {name: [] for name in dicts}
    for line in rows_path.read_text().splitlines():
        row = json.loads(line)
        if row["name"] in rows and row["seed"] < seeds:
            rows[row.pop("name")].append(row)
    for name in rows:
        rows[name].sort(key=lambda r: r["seed"])
    return {"about": "Blender's Sapling add-on growing the harness dictionaries of bench_sapling_fidelity.py "
                     "(benchmarks/sapling_runner.py), seeds 0..seeds-1 each: seconds of the add-on's operator, "
                     "bark height and crown radius of the bevelled curve (m), splines per level, leaves.",
            "versions": versions, "seeds": seeds, "wall_seconds_last_run": round(wall, 1),
            "dictionaries": dicts, "trees": rows}


# ---------------------------------------------------------------- tables
def _fmt(q: np.ndarray) -> str:
    digits = 0 if q[1] >= 100 else 2
    return f"{q[1]:.{digits}f} ({q[2] - q[0]:.{digits}f})"


def worst_first(records: list[dict]) -> list[str]:
    """Dictionary names, the one whose worst measure lies farthest outside its band first (no data counts as
    worst); among those within their bands, the largest ratio away from 1 first."""
    worst: dict[str, float] = {}
    for r in records:
        away = 0.0 if r["missing"] else abs(np.log(max(r["ratio"], 1e-9))) * 1e-3
        worst[r["name"]] = max(worst.get(r["name"], 0.0), r["score"], away)
    return sorted(worst, key=lambda name: (-worst[name], name))


def comparison_table(bench: Benchmark, title: str, records: list[dict]) -> None:
    """The comparison, dictionaries worst first, then their measures worst first."""
    rank = {name: i for i, name in enumerate(worst_first(records))}
    rows = []
    for r in sorted(records, key=lambda r: (rank[r["name"]], -r["score"])):
        if r["missing"]:
            rows.append((r["name"], r["measure"], f"{r['n'][0]}/{r['n'][1]}", "-", "-", "-", "-", "NO DATA"))
            continue
        rows.append((r["name"], r["measure"], f"{r['n'][0]}/{r['n'][1]}", _fmt(r["ours"]), _fmt(r["sapling"]),
                     f"{r['ratio']:.3f}", f"[{r['lo']:.3f}, {r['hi']:.3f}]",
                     f"DIFFERS (+-{tolerance(r['measure']) * 100:.0f}%)" if r["flag"] else ""))
    bench.table(title, ["dictionary", "measure", "n ours/sap", "ours median (IQR)", "sapling median (IQR)", "ratio",
                        "95% interval", "flag"], rows, notes=[summary(records)])


def summary(records: list[dict]) -> str:
    """One line: how many dictionaries and (dictionary, measure) pairs differ outside the bootstrap noise."""
    names = sorted({r["name"] for r in records})
    flagged = sorted({r["name"] for r in records if r["flag"]})
    by_measure = {}
    for r in records:
        key = "stems" if r["measure"].startswith("stems") else r["measure"]
        by_measure.setdefault(key, set())
        if r["flag"]:
            by_measure[key].add(r["name"])
    parts = ", ".join(f"{k} {len(v)}" for k, v in by_measure.items())
    return (f"{len(flagged)} of {len(names)} dictionaries differ from Sapling outside the bootstrap noise "
            f"(height/crown band 10 %, stems and leaves 15 %); by measure: {parts}")


def speedup(ours: dict[str, list[dict]], sapling: dict[str, list[dict]]) -> tuple[float, dict[str, float]]:
    """Median over dictionaries of Sapling's median seconds per tree over ours (grow + mesh + GLB)."""
    per = {}
    for name in ours:
        mine = [r["seconds"] for r in ours[name] if "error" not in r]
        theirs = [r["seconds"] for r in sapling[name] if "error" not in r]
        if mine and theirs:
            per[name] = float(np.median(theirs) / np.median(mine))
    return float(np.median(list(per.values()))), per


# ---------------------------------------------------------------- picture
_MEASURE_COLOURS = {"bark_height_m": (31, 119, 180), "crown_radius_m": (44, 160, 44), "stems": (214, 39, 40),
                    "leaves": (148, 103, 189)}


def write_png(records: list[dict], path: Path, lo: float = 0.25, hi: float = 4.0) -> None:
    """Ratio intervals per dictionary on a log axis, one colour per measure, the 10 % band shaded."""
    names = worst_first(records)
    row_h, left, width = 18, 190, 760
    image = Image.new("RGB", (left + width + 20, row_h * (len(names) + 3)), "white")
    draw = ImageDraw.Draw(image)

    def x_of(ratio: float) -> float:
        return left + width * (np.log(np.clip(ratio, lo, hi)) - np.log(lo)) / (np.log(hi) - np.log(lo))

    top, bottom = row_h, row_h * (len(names) + 1)
    draw.rectangle([x_of(0.9), top, x_of(1.1), bottom], fill=(230, 230, 230))
    for tick in (0.25, 0.5, 1.0, 2.0, 4.0):
        draw.line([x_of(tick), top, x_of(tick), bottom], fill=(150, 150, 150))
        draw.text((x_of(tick) - 8, bottom + 4), f"{tick:g}", fill="black")
    draw.text((left, 2), "treefarm / Sapling, median ratio and 95% bootstrap interval (log axis)", fill="black")
    for i, name in enumerate(names):
        y = top + row_h * i + row_h / 2
        draw.text((4, y - 6), name, fill="black")
        mine = [r for r in records if r["name"] == name and not r["missing"]]
        for j, r in enumerate(mine):
            key = "stems" if r["measure"].startswith("stems") else r["measure"]
            dy = (j - len(mine) / 2) * 2
            colour = _MEASURE_COLOURS[key]
            draw.line([x_of(r["lo"]), y + dy, x_of(r["hi"]), y + dy], fill=colour, width=1)
            cx = x_of(r["ratio"])
            draw.ellipse([cx - 2, y + dy - 2, cx + 2, y + dy + 2], fill=colour)
    for k, (key, colour) in enumerate(_MEASURE_COLOURS.items()):
        draw.text((left + 150 * k, bottom + 20 - 4), key, fill=colour)
    path.parent.mkdir(parents=True, exist_ok=True)
    image.save(path)


# ---------------------------------------------------------------- main
def load_reference(path: Path, harness: list[HarnessDict]) -> dict:
    """The cached Sapling side; names the dictionaries whose Sapling input changed since it was recorded."""
    reference = json.loads(path.read_text())
    stale = stale_dictionaries(reference, harness)
    if stale:
        print(f"note: the Sapling cache {path} was recorded for other dictionaries than these: {', '.join(stale)} "
              f"(rerun with --rerun-sapling)")
    return reference


def main() -> None:
    parser = arguments(__doc__)
    parser.add_argument("--seeds", type=int, default=N_SEEDS)
    parser.add_argument("--preset-dicts", type=int, default=N_PRESET_DICTS)
    parser.add_argument("--sapling-cache", type=Path, default=FIDELITY_REFERENCE,
                        help="the Sapling side's figures (JSON)")
    parser.add_argument("--rerun-sapling", action="store_true", help="grow the Sapling side again into the cache")
    parser.add_argument("--sapling-only", action="store_true", help="with --rerun-sapling: stop after Sapling")
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "sapling_fidelity", help="Sapling's scratch")
    parser.add_argument("--png", type=Path, default=ROOT / "out" / "sapling_fidelity.png")
    parser.add_argument("--bootstrap-seed", type=int, default=0)
    args = parser.parse_args()
    bench = Benchmark("sapling_fidelity", "Weber-Penn trees against Sapling's, in distribution", args)
    harness = harness_dictionaries(args.preset_dicts)

    if args.rerun_sapling:
        reference = run_sapling(harness, args.seeds, args.work)
        args.sapling_cache.write_text(json.dumps(reference, indent=None, separators=(",", ":")) + "\n")
        print(f"Sapling side: {len(harness)} dictionaries x {args.seeds} seeds in "
              f"{reference['wall_seconds_last_run']:.0f} s, written to {args.sapling_cache}")
        if args.sapling_only:
            return
    else:
        reference = load_reference(args.sapling_cache, harness)
    sapling = {h.name: reference["trees"].get(h.name, []) for h in harness}

    ours = grow_treefarm(harness, args.seeds)
    records = compare(ours, sapling, np.random.default_rng(args.bootstrap_seed))
    comparison_table(bench, f"treefarm against Sapling {reference['versions'].get('sapling')} (Blender "
                     f"{reference['versions'].get('blender')}), {args.seeds} seeds per side; median (IQR); ratio of "
                     "medians with its bootstrap 95 % interval", records)
    for side, rows_of in (("treefarm", ours), ("Sapling", sapling)):
        failed = {name: [r["error"] for r in rows if "error" in r] for name, rows in rows_of.items()}
        for name, errors in failed.items():
            if errors:
                bench.note(f"{side} failed {len(errors)} of {len(rows_of[name])} trees of {name}: {errors[0]}")
    median, per = speedup(ours, sapling)
    slowest = min(per, key=per.get)
    bench.figure(f"speed-up on Sapling, median over {len(per)} dictionaries", median, "x",
                 f"Sapling seconds / treefarm seconds per tree (grow + mesh + GLB, one process); least "
                 f"{per[slowest]:.1f}x on {slowest}; target >= 20x, goal 50x")
    write_png(records, args.png)
    bench.note(f"picture: {args.png}")
    bench.write()


if __name__ == "__main__":
    main()
