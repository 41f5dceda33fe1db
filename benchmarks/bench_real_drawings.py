"""Real drawings of trees, made by people outside this project, through the params method with its fit to the
drawing off and on: how well the result, redrawn in the drawing's view, covers what was drawn.

Drawings: `../shared/data/sketches/` beside the repository (--data), read there and never copied into the project;
each subfolder is a set (tuberlin_trees: crowd workers' pen drawings, black on white; mouse_branches_foliage: mouse
drawings of another tool, colour strokes on black). No ground truth comes with them, so the score is the one
`farm evaluate --inputs` gives a sketch without a reference (`farm.evaluate.inputs.drawing_fit`): the result's
filled outline against the drawing's (`reconstruct.fitting`: each cut to its box, scaled to one height, pen gaps
closed and enclosed paper filled), intersection over union, the measure the fit maximises.

Budgets (--evals): 0 (the network's guess grown as it is), the default (`DEFAULT_FIT_EVALS`) and a larger one.
Per set and budget: median and quartiles of the outline IoU, drawings below 0.3 and above 0.75, and seconds per
drawing on one core (the image read and `reconstruct.from_params`, network included; every thread pool and the
process pinned to one core by `benchmarks.harness.pin_threads`): the process's CPU seconds, what one free core
takes (the wall clock beside it, longer on a machine others share). The score against evaluations: the median over
drawings of the best score after 1, 2, 4, ... evaluations of the largest budget's fits (a fit's first k evaluations
are what a budget of k evaluates), as a table and a figure (--figure).
Targets (issue 49, on 65 drawings): median >= 0.75, at most 2 in 65 below 0.3, <= 5 s per drawing at the default
budget.

Run: python -m benchmarks.bench_real_drawings [--data ../shared/data/sketches] [--evals 0,32,128]
     [--figure docs/images/fit_real_drawings.png]
"""
from __future__ import annotations

from benchmarks.harness import ROOT, Benchmark, arguments, pin_threads

if __name__ == "__main__":  # before numpy loads; a test that imports this module keeps its own thread pools
    pin_threads(one_core=True)

import io  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from farm.dataset import IMAGE_SUFFIXES, read_image  # noqa: E402
from farm.evaluate.inputs import drawing_fit  # noqa: E402
from reconstruct.from_params import from_params  # noqa: E402
from reconstruct.methods import DEFAULT_FIT_EVALS  # noqa: E402
from reconstruct.networks import predictor  # noqa: E402
from renderers import ViewRenderer  # noqa: E402

DATA = ROOT.parent / "shared" / "data" / "sketches"
FIGURE = ROOT / "docs" / "images" / "fit_real_drawings.png"
LOW, HIGH = 0.3, 0.75          # the thresholds: a miss, and a tree that looks like the drawing
TARGET_MEDIAN, TARGET_S = 0.75, 5.0
TARGET_LOW_SHARE = 2 / 65      # at most 2 of the 65 drawings below LOW


@dataclass
class Drawing:
    """One drawing's results: per budget its outline IoU, seconds (wall clock and this process's CPU) and species;
    the largest budget's best scores after each evaluation."""

    set_name: str
    name: str
    scores: dict[int, float]
    seconds: dict[int, float]
    cpu_seconds: dict[int, float]
    species: dict[int, str]
    best: list[float]


def drawings(folder: Path) -> dict[str, list[Path]]:
    """set name -> its drawings (image files of each subfolder, sorted), subfolders by name."""
    sets = {}
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()):
        found = sorted(p for p in sub.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES)
        if found:
            sets[sub.name] = found
    return sets


def run_drawing(path: Path, set_name: str, budgets: list[int], net, renderer: ViewRenderer) -> Drawing:
    scores, seconds, cpu_seconds, species, best = {}, {}, {}, {}, []
    for evals in budgets:
        start, start_cpu = time.perf_counter(), time.process_time()
        image = read_image(str(path))
        result = from_params(image, net=net, fit_evals=evals, renderer=renderer)
        seconds[evals], cpu_seconds[evals] = time.perf_counter() - start, time.process_time() - start_cpu
        record = drawing_fit(result, image, renderer)
        scores[evals], species[evals] = record.score, str(result.params["species"])
        if evals == max(budgets):
            best = record.trace.best
    return Drawing(set_name, path.name, scores, seconds, cpu_seconds, species, best)


def curve_points(evals: int) -> list[int]:
    """1, 2, 4, ... up to `evals`, and `evals` itself."""
    points = [1 << k for k in range(evals.bit_length()) if 1 << k <= evals]
    return points + ([evals] if evals not in points else [])


def quartiles(values) -> tuple[float, float, float]:
    q25, q50, q75 = np.percentile(np.asarray(values, float), [25, 50, 75])
    return float(q50), float(q25), float(q75)


def write_figure(path: Path, groups: dict[str, list[Drawing]], points: list[int]) -> None:
    """Median best-so-far outline IoU against evaluations, per set and over all (quartile band), beside the
    budget-0 median and the target."""
    import matplotlib  # here: the plot is the benchmark's last step, and only with --figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    fig.subplots_adjust(left=0.11, right=0.97, top=0.9, bottom=0.13)
    for name, group in groups.items():
        curve = np.array([[d.best[min(k, len(d.best)) - 1] for d in group] for k in points])
        median, q25, q75 = (np.percentile(curve, q, axis=1) for q in (50, 25, 75))
        style = {"linewidth": 2.2, "color": "black"} if name == "all" else {"linewidth": 1.2}
        ax.plot(points, median, marker="o", markersize=3, label=f"{name} ({len(group)})", **style)
        if name == "all":
            ax.fill_between(points, q25, q75, color="grey", alpha=0.2, label="all: quartiles")
    ax.axhline(TARGET_MEDIAN, color="green", linestyle="--", linewidth=1, label=f"target median {TARGET_MEDIAN}")
    if DEFAULT_FIT_EVALS in points:
        ax.axvline(DEFAULT_FIT_EVALS, color="grey", linestyle=":", linewidth=1, label="default budget")
    ax.set_xscale("log", base=2)
    ax.set_xticks(points, [str(k) for k in points])
    ax.set_ylim(0, 1)
    ax.set_xlabel("candidate trees evaluated (--fit-evals)")
    ax.set_ylabel("outline IoU, median best so far")
    ax.set_title("params method fitted to real drawings")
    ax.legend(fontsize=7, loc="lower right")
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(buffer.getvalue())


def main(argv=None) -> None:
    parser = arguments(__doc__)
    parser.add_argument("--data", type=Path, default=DATA, help=f"folder of drawing sets (default {DATA})")
    parser.add_argument("--evals", default=f"0,{DEFAULT_FIT_EVALS},{4 * DEFAULT_FIT_EVALS}",
                        help="comma-separated fit budgets (default 0, the default budget and four times it)")
    parser.add_argument("--limit", type=int, default=None, help="at most N drawings per set (a quick look)")
    parser.add_argument("--figure", type=Path, default=FIGURE, help="the score-against-evaluations PNG")
    parser.add_argument("--models", default=None, help="model registry URI (default: the shipped models/)")
    args = parser.parse_args(argv)
    budgets = sorted({int(v) for v in args.evals.split(",") if v.strip()})
    if not budgets or budgets[0] < 0 or budgets[-1] < 1:
        parser.error(f"--evals {args.evals}: allowed budgets >= 0, the largest >= 1")
    if not args.data.is_dir():
        parser.error(f"--data {args.data} is not a folder of drawing sets")
    sets = {name: paths[:args.limit] for name, paths in drawings(args.data).items()}
    if not sets:
        parser.error(f"--data {args.data} has no subfolder of drawings")

    bench = Benchmark("real_drawings", "params method fitted to real drawings: outline IoU, seconds per drawing",
                      args)
    net = predictor("sketchnet", args.models)
    renderer = ViewRenderer(256)
    results: list[Drawing] = []
    try:
        first = next(iter(sets.values()))[0]
        from_params(read_image(str(first)), net=net, fit_evals=1, renderer=renderer)  # warm-up: untimed
        for set_name, paths in sets.items():
            for path in paths:
                results.append(run_drawing(path, set_name, budgets, net, renderer))
                done = results[-1]
                print(f"{set_name}/{path.name}: " + ", ".join(
                    f"{k}: {done.scores[k]:.3f} in {done.cpu_seconds[k]:.1f} s" for k in budgets), flush=True)
    finally:
        renderer.close()

    groups = {**{name: [d for d in results if d.set_name == name] for name in sets}, "all": results}
    rows = []
    for name, group in groups.items():
        for evals in budgets:
            values = [d.scores[evals] for d in group]
            median, q25, q75 = quartiles(values)
            cpu = [d.cpu_seconds[evals] for d in group]
            rows.append([name, evals, len(group), median, q25, q75, sum(v < LOW for v in values),
                         sum(v > HIGH for v in values), float(np.median(cpu)), float(np.max(cpu)),
                         float(np.median([d.seconds[evals] for d in group]))])
    bench.table("outline IoU per set and fit budget", ["set", "fit evals", "drawings", "median", "q25", "q75",
                                                       f"< {LOW}", f"> {HIGH}", "CPU s / drawing", "CPU s max",
                                                       "wall s / drawing"], rows,
                notes=[f"target (issue 49, 65 drawings): median >= {TARGET_MEDIAN}, at most 2 of 65 below {LOW}, "
                       f"<= {TARGET_S:g} s per drawing at the default budget ({DEFAULT_FIT_EVALS})",
                       "issue 49 before fitting: median 0.41 (quartiles 0.24, 0.53), 23 of 65 below 0.3, none above "
                       "0.75 (a measure of its own; budget 0 here is this measure of the same method)"])
    largest = budgets[-1]
    points = curve_points(largest)
    curve_rows = []
    for k in points:
        row = [k]
        for group in groups.values():
            # A fit that stopped at its face budget keeps its best for the rest of the evaluations.
            row.append(float(np.median([d.best[min(k, len(d.best)) - 1] for d in group])))
        curve_rows.append(row)
    bench.table(f"score against evaluations: median best outline IoU so far (fits of budget {largest})",
                ["evals", *groups], curve_rows,
                notes=["a fit's first k evaluations are what --fit-evals k evaluates (same seed), so each row is "
                       "what that budget gives"])
    bench.table("per drawing: outline IoU (species read) per budget", ["set", "drawing", *map(str, budgets)],
                [[d.set_name, d.name, *[f"{d.scores[k]:.3f} ({d.species[k]})" for k in budgets]] for d in results])
    default = DEFAULT_FIT_EVALS if DEFAULT_FIT_EVALS in budgets else largest
    all_scores = [d.scores[default] for d in results]
    bench.figure("median outline IoU, budget 0", float(np.median([d.scores[0] for d in results]))
                 if 0 in budgets else float("nan"), "IoU")
    bench.figure(f"median outline IoU, budget {default}", float(np.median(all_scores)), "IoU",
                 f"target >= {TARGET_MEDIAN}")
    bench.figure(f"share below {LOW}, budget {default}", float(np.mean([v < LOW for v in all_scores])), "share",
                 f"target <= {TARGET_LOW_SHARE:.3f} (2 of 65)")
    bench.figure(f"CPU seconds per drawing, budget {default}",
                 float(np.median([d.cpu_seconds[default] for d in results])), "s", f"target <= {TARGET_S:g} s, one core")
    if not args.no_results:
        write_figure(args.figure, groups, points)
        print(f"figure: {args.figure.relative_to(ROOT) if args.figure.is_relative_to(ROOT) else args.figure}")
    bench.write()


if __name__ == "__main__":
    main()
