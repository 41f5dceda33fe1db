"""Differential harness: treefarm's Weber-Penn generator against Blender's Sapling add-on, in distribution.

Each harness dictionary (Sapling's own presets, TreeSketchNet's dictionaries, dictionaries sampled from our presets
as Sapling ranges) is grown over seeds by both; per dictionary it prints median and IQR of bark height, crown
radius, stems per level and leaf count, the treefarm/Sapling ratio of medians with a bootstrap 95 % interval, worst
first, and the speed ratio. The Sapling side is read from benchmarks/references/sapling_fidelity.json unless
--rerun-sapling. Run: .venv/bin/python benchmarks/bench_sapling_fidelity.py [--png out/sapling_fidelity.png]
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core, before numpy loads
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from PIL import Image, ImageDraw  # noqa: E402

import species  # noqa: E402
from farm.table import format_table  # noqa: E402
from species.weber_penn.sapling_preset import REALIZED_ONLY_KEYS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
SAPLING_PRESETS = SHARED / "tools" / "sapling" / "add_curve_sapling" / "presets"
TSN_DICTS = SHARED / "data" / "sapling"
REFERENCE = ROOT / "benchmarks" / "references" / "sapling_fidelity.json"
RUNNER = ROOT / "benchmarks" / "sapling_runner.py"
BLENDER_PYTHON = ROOT / ".venv-blender" / "bin" / "python"
N_PRESET_DICTS = 30   # dictionaries sampled from our Weber-Penn presets
N_SEEDS = 24
# Relative band within which a ratio of medians counts as the same: height and crown 10 %, counts 15 %.
TOLERANCE = {"bark_height_m": 0.10, "crown_radius_m": 0.10, "stems": 0.15, "leaves": 0.15}
# Sapling's variation keys that our presets record as realized draws, per tree (`draws: realized`).
RANGE_KEYS = ("scaleV", "scaleV0", "leafScaleV", "curveV", "splitAngleV")


# ---------------------------------------------------------------- dictionaries
class _UpperBounds:
    """Stands in for a Generator and returns the upper bound of every uniform draw: read through a preset's
    recorded-draw callables, it gives the half-width of each range they draw from."""

    def uniform(self, low=0.0, high=1.0, size=None):
        return np.broadcast_to(np.asarray(high, float), np.shape(high) if size is None else size).copy()


def preset_ranges(preset) -> dict:
    """Sapling's range keys for one of our Weber-Penn presets, read from the draws it records per tree:
    scaleV +-metres, scaleV0 and leafScaleV +-fractions, curveV and splitAngleV degrees per level."""
    bounds = {key: preset.ranges[key](_UpperBounds(), {}) for key in
              ("scaleV", "scaleV0", "leafScaleV", "curveV1", "splitAngleV1")}
    return {"scaleV": float(bounds["scaleV"]), "scaleV0": float(bounds["scaleV0"]) - 1.0,
            "leafScaleV": float(bounds["leafScaleV"]) - 1.0, "curveV": np.asarray(bounds["curveV1"]).tolist(),
            "splitAngleV": np.asarray(bounds["splitAngleV1"]).tolist()}


def preset_as_ranges(preset, rng: np.random.Generator) -> dict:
    """One dictionary sampled from our preset (its jittered keys drawn by `rng`), with the preset's per-tree draws
    replaced by Sapling's ranges and `draws: ranges`; the tree's own seed is set per grown tree."""
    params = species.sample(preset.name, rng)
    # splitByLen too: these dictionaries grow with Sapling's defaults on both sides (the committed Sapling run).
    for key in (*REALIZED_ONLY_KEYS, *RANGE_KEYS, "seed", "splitByLen"):
        params.pop(key, None)
    return {**params, **preset_ranges(preset), "draws": "ranges"}


def realized_for_sapling(params: dict) -> dict:
    """A TreeSketchNet dictionary as Sapling is given it: scale, scale0 and leafScale set to the realized values
    (scale + scaleV, scale0 * scaleV0, leafScale * leafScaleV) and those three ranges zero; the other stored
    draws are no Sapling keys and drop out."""
    out = dict(params)
    out["scale"] = params["scale"] + params.get("scaleV", 0.0)
    out["scale0"] = params.get("scale0", 1.0) * params.get("scaleV0", 1.0)
    out["leafScale"] = params["leafScale"] * params.get("leafScaleV", 1.0)
    out.update(scaleV=0.0, scaleV0=0.0, leafScaleV=0.0)
    return out


@dataclass(frozen=True)
class HarnessDict:
    """One harness dictionary: what treefarm grows and what Sapling is given (the same but for TreeSketchNet's)."""

    name: str
    kind: str        # sapling_preset, treesketchnet or our_preset
    treefarm: dict
    sapling: dict


def harness_dictionaries(n_preset_dicts: int = N_PRESET_DICTS) -> list[HarnessDict]:
    """Sapling's presets, TreeSketchNet's dictionaries, and `n_preset_dicts` sampled from our Weber-Penn presets
    in turn (dictionary i from preset i mod P, drawn with default_rng(i))."""
    out = []
    for path in sorted(SAPLING_PRESETS.glob("*.py")):
        params = species.sapling_preset(path)
        out.append(HarnessDict(f"sapling:{path.stem}", "sapling_preset", params, params))
    for path in sorted(TSN_DICTS.glob("*.json")):
        params = json.loads(path.read_text())
        # rSplits2 is TreeSketchNet's one stored split draw for the whole tree; stock Sapling has no such key and
        # draws each split decision afresh, so treefarm is given the dictionary without it to grow the same tree.
        mine = {k: v for k, v in params.items() if k != "rSplits2"}
        out.append(HarnessDict(f"tsn:{path.stem}", "treesketchnet", mine, realized_for_sapling(params)))
    presets = species.list_presets("weber_penn")
    for i in range(n_preset_dicts):
        preset = presets[i % len(presets)]
        params = preset_as_ranges(preset, np.random.default_rng(i))
        out.append(HarnessDict(f"ours:{preset.name}_{i // len(presets)}", "our_preset", params, params))
    return out


# ---------------------------------------------------------------- the two sides
def bark_extent(vertices: np.ndarray) -> tuple[float, float]:
    """Bark height (z range) and crown radius (farthest vertex from the z axis) of bark vertices (V, 3), metres:
    the measure sapling_runner.py takes of Sapling's bevelled curve."""
    if len(vertices) == 0:
        return 0.0, 0.0
    v = np.asarray(vertices, np.float64)
    return float(v[:, 2].max() - v[:, 2].min()), float(np.sqrt((v[:, :2] ** 2).sum(axis=1)).max())


def treefarm_figures(params: dict, seed: int) -> dict:
    """One treefarm tree at `seed`: seconds for grow + mesh + GLB, bark height and crown radius of the bark mesh,
    branches per order (Sapling's splines per level: a split's new arm is a branch of the same order), leaves."""
    params = {**params, "seed": seed}
    start = time.perf_counter()
    try:
        skeleton = species.grow(params, species.rng_for(params))
        mesh = species.build_mesh(skeleton, params)
        mesh.to_glb()
    except (species.TreefarmError, ValueError) as exc:  # refused, or a range numpy cannot draw from: reported
        return {"error": f"{type(exc).__name__}: {exc}"[:300]}
    seconds = time.perf_counter() - start
    height, crown = bark_extent(mesh.bark.vertices)
    return {"seconds": round(seconds, 5), "bark_height_m": round(height, 4), "crown_radius_m": round(crown, 4),
            "stems_per_level": skeleton.order_counts().astype(int).tolist(), "leaves": int(skeleton.n_leaves)}


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


# ---------------------------------------------------------------- comparison
def bootstrap_ratio(ours, theirs, rng: np.random.Generator, n_boot: int = 2000,
                    level: float = 0.95) -> tuple[float, float, float]:
    """Ratio of medians ours/theirs and its percentile bootstrap interval (both samples resampled, vectorised).
    0/0 counts as 1 and x/0 as infinity."""
    a, b = np.asarray(ours, float), np.asarray(theirs, float)
    med_a = np.median(a[rng.integers(0, len(a), (n_boot, len(a)))], axis=1)
    med_b = np.median(b[rng.integers(0, len(b), (n_boot, len(b)))], axis=1)
    point = _ratio(np.median(a), np.median(b))
    lo, hi = np.quantile(_ratio(med_a, med_b), [(1 - level) / 2, (1 + level) / 2], method="inverted_cdf")
    return float(point), float(lo), float(hi)


def _ratio(num, den):
    num, den = np.asarray(num, float), np.asarray(den, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1), np.where(num > 0, np.inf, 1.0))


def _measures(rows: list[dict], n_levels: int) -> dict[str, np.ndarray]:
    """Per measure, the (seeds,) values of the rows that grew: height, crown, stems of each level, leaves."""
    ok = [r for r in rows if "error" not in r]
    stems = np.zeros((len(ok), n_levels))
    for i, r in enumerate(ok):
        stems[i, :len(r["stems_per_level"])] = r["stems_per_level"][:n_levels]
    out = {"bark_height_m": np.array([r["bark_height_m"] for r in ok]),
           "crown_radius_m": np.array([r["crown_radius_m"] for r in ok])}
    out.update({f"stems_L{level}": stems[:, level] for level in range(n_levels)})
    out["leaves"] = np.array([r["leaves"] for r in ok], float)
    return out


def _tolerance(measure: str) -> float:
    return TOLERANCE["stems" if measure.startswith("stems") else measure]


def outside_band(lo: float, hi: float, tol: float) -> float:
    """How far (log ratio) a ratio interval lies outside the band [1 - tol, 1 + tol]; 0 when it overlaps it."""
    with np.errstate(divide="ignore"):
        return float(max(0.0, np.log(lo / (1 + tol)), np.log((1 - tol) / hi) if hi > 0 else np.inf))


def compare(ours: dict[str, list[dict]], sapling: dict[str, list[dict]], rng: np.random.Generator) -> list[dict]:
    """One record per (dictionary, measure): medians and IQRs of both sides, ratio with interval, flag, score."""
    records = []
    for name in ours:
        levels = max([len(r.get("stems_per_level", [])) for r in ours[name] + sapling[name]] + [1])
        mine, theirs = _measures(ours[name], levels), _measures(sapling[name], levels)
        for measure in mine:
            a, b = mine[measure], theirs[measure]
            if len(a) == 0 or len(b) == 0:
                records.append({"name": name, "measure": measure, "n": (len(a), len(b)), "missing": True,
                                "flag": True, "score": np.inf})
                continue
            point, lo, hi = bootstrap_ratio(a, b, rng)
            score = outside_band(lo, hi, _tolerance(measure))
            records.append({"name": name, "measure": measure, "n": (len(a), len(b)), "missing": False,
                            "ours": np.percentile(a, [25, 50, 75]), "sapling": np.percentile(b, [25, 50, 75]),
                            "ratio": point, "lo": lo, "hi": hi, "flag": score > 0, "score": score})
    return records


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


def print_table(records: list[dict]) -> None:
    """The comparison, dictionaries worst first, then their measures worst first."""
    rank = {name: i for i, name in enumerate(worst_first(records))}
    rows = []
    for r in sorted(records, key=lambda r: (rank[r["name"]], -r["score"])):
        if r["missing"]:
            rows.append((r["name"], r["measure"], f"{r['n'][0]}/{r['n'][1]}", "-", "-", "-", "-", "NO DATA"))
            continue
        rows.append((r["name"], r["measure"], f"{r['n'][0]}/{r['n'][1]}", _fmt(r["ours"]), _fmt(r["sapling"]),
                     f"{r['ratio']:.3f}", f"[{r['lo']:.3f}, {r['hi']:.3f}]",
                     f"DIFFERS (+-{_tolerance(r['measure']) * 100:.0f}%)" if r["flag"] else ""))
    print(format_table(["dictionary", "measure", "n ours/sap", "ours median (IQR)", "sapling median (IQR)",
                        "ratio", "95% interval", "flag"], rows))


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
def sapling_input(params: dict, sapling_keys) -> dict:
    """What of a dictionary reaches Sapling: its keys that are the add-on's properties (the seed set per tree),
    as JSON values."""
    return json.loads(json.dumps({k: params[k] for k in sorted(params) if k in set(sapling_keys) - {"seed"}}))


def stale_dictionaries(reference: dict, harness: list[HarnessDict]) -> list[str]:
    """Harness dictionaries whose input to Sapling differs from the one the cached figures were grown from."""
    keys = reference["versions"]["sapling_keys"]
    return [h.name for h in harness if h.name not in reference["dictionaries"]
            or sapling_input(reference["dictionaries"][h.name], keys) != sapling_input(h.sapling, keys)]


def load_reference(path: Path, harness: list[HarnessDict]) -> dict:
    """The cached Sapling side; names the dictionaries whose Sapling input changed since it was recorded."""
    reference = json.loads(path.read_text())
    stale = stale_dictionaries(reference, harness)
    if stale:
        print(f"note: the Sapling cache {path} was recorded for other dictionaries than these: {', '.join(stale)} "
              f"(rerun with --rerun-sapling)")
    return reference


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=N_SEEDS)
    parser.add_argument("--preset-dicts", type=int, default=N_PRESET_DICTS)
    parser.add_argument("--sapling-cache", type=Path, default=REFERENCE, help="the Sapling side's figures (JSON)")
    parser.add_argument("--rerun-sapling", action="store_true", help="grow the Sapling side again into the cache")
    parser.add_argument("--sapling-only", action="store_true", help="with --rerun-sapling: stop after Sapling")
    parser.add_argument("--work", type=Path, default=ROOT / "out" / "sapling_fidelity", help="Sapling's scratch")
    parser.add_argument("--png", type=Path, default=ROOT / "out" / "sapling_fidelity.png")
    parser.add_argument("--bootstrap-seed", type=int, default=0)
    args = parser.parse_args()
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
    print(f"treefarm vs Sapling {reference['versions'].get('sapling')} (Blender {reference['versions'].get('blender')}),"
          f" {args.seeds} seeds per side; median (IQR); ratio of medians with its bootstrap 95 % interval\n")
    print_table(records)
    print("\n" + summary(records))
    for side, rows_of in (("treefarm", ours), ("Sapling", sapling)):
        failed = {name: [r["error"] for r in rows if "error" in r] for name, rows in rows_of.items()}
        for name, errors in failed.items():
            if errors:
                print(f"{side} failed {len(errors)} of {len(rows_of[name])} trees of {name}: {errors[0]}")
    median, per = speedup(ours, sapling)
    slowest = min(per, key=per.get)
    print(f"speed: Sapling seconds / treefarm seconds per tree (grow + mesh + GLB, one process), median over "
          f"{len(per)} dictionaries: {median:.1f}x (least {per[slowest]:.1f}x on {slowest}; target >= 20x, goal 50x)")
    write_png(records, args.png)
    print(f"picture: {args.png}")


if __name__ == "__main__":
    main()
