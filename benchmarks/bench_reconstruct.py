"""Quality and speed of the drawing reconstructions on held-out trees, beside the papers' figures.

Methods: the registry's (`reconstruct.methods.METHODS`) whose inputs are rendered drawings; the three below have
runners of their own, any other runs as `run_drawn` (its inputs rendered in the rig the registry names, grown at
the true height, scored like the others). Trees: grown here from each method's dataset spec (its species; the tree
seeds of a bench-own job seed, never a training spec's, so the shipped models never saw them), rendered as the spec
renders them:
- params (seed 004): TreeSketchNet reads the `tsn4` front view's `sketch_tsn`, the Weber-Penn generator grows the
  dictionary. Parameter head scores (1 - RMSE) x 100 with the model's codec, species accuracy, height and crown
  errors, and the rotation sweep: the network on each view of rig `orbit:N:10` (paper: 72 views, HDD ~0.03).
- sketch-depth (seed 000): the `two-view` front view's `sketch_edges` and `trunk_strokes` through both pix2pix
  networks (`reconstruct.from_sketch`); their foreground depth error against the GT `silhouette_envelope` /
  `trunk_depth` (cut to the network's crop as training cut them), the traced main skeleton against the GT main branches; a
  second column grows from the GT maps (`reconstruct.from_maps`), the networks' share of the error.
- two-view (seed 001): the `two-view:shared` front and side `sketch_strokes` (1-px lines) and
  `sketch_strokes_brush` into `reconstruct.two_view`.
Every method is scored with the same geometry metrics (`reconstruct.metrics`): silhouette IoU in the input view(s)
and in unseen views (orbit azimuths 45 deg apart that no input looked along), node and surface Hausdorff / Chamfer
over the GT height, node Hausdorff in the unit orthographic cube, skeleton F1 AUC, height and crown errors. The
baseline column is another tree of the true preset (a prior that knows the species), the floor a reconstruction
must beat.

Alignment: every tree stands with its base at the origin, Z up, in metres. The params tree is grown at the GT
height (`from_params(height=...)`; the network's own size guess has its row). The sketch-depth reconstruction is
grown in the drawing's frame (`reconstruct.networks.drawing_camera`: looking along +Y like the front view, base
at the lowest stroke point) scaled to `height` = the GT `Skeleton.height` (nodes and leaves: the top of the
silhouette the drawing shows). The two-view drawings show only the main branches, so their `height` is the top of
the GT main branches (what the strokes span); its X and Y are the front and side image axes, world X and Y.

Speed: seconds per stage per tree, networks included (ONNX Runtime and every other thread pool run
single-threaded: `benchmarks.harness.pin_threads`). For one core: taskset -c 0 python -m benchmarks.bench_reconstruct
Beside seed 000's Table 3.1 (i7-7700HQ + GTX 1080 Ti: trunk 0.069-0.083 s, silhouette 0.058-0.072 s, growth
1.07-1.53 s) and seed 001 (7 s for a peach tree on a 2 GHz dual core); target: each method under 2 s per tree.
Writes a contact sheet (input, GT and reconstruction in the input view and in an unseen view) to --out, and the
tables to benchmarks/results/reconstruct.json.

Run: python -m benchmarks.bench_reconstruct [--trees 12] [--methods params,sketch-depth,two-view]
     [--sweep-trees 3] [--sweep-views 72] [--surface-samples 100000] [--sheet-trees 3] [--out out/bench_reconstruct]
"""
from __future__ import annotations

from benchmarks.harness import ROOT, Benchmark, arguments, pin_threads

if __name__ == "__main__":  # before numpy loads; a test that imports this module keeps its own thread pools
    pin_threads()

import itertools  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import reconstruct  # noqa: E402
import species  # noqa: E402
from farm.jobs import load_spec  # noqa: E402
from farm.tree_chain import stage_rngs, tree_seed  # noqa: E402
from reconstruct import metrics  # noqa: E402
from reconstruct.from_sketch import DEFAULT_SPECIES  # noqa: E402
from reconstruct.fit_budget import DEFAULT_FIT_EVALS  # noqa: E402
from reconstruct.methods import METHODS, Method, RunOptions  # noqa: E402
from reconstruct.networks import predictor  # noqa: E402
from reconstruct.scoring import METRICS, TreeScorer, depth_picture, main_branch_nodes, network_depth_error  # noqa: E402
from renderers import RenderedView, ViewRenderer, write_contact_sheet  # noqa: E402
from renderers.camera import parse_rig  # noqa: E402
from species.errors import TreefarmError  # noqa: E402

# Each method's dataset spec: its species and its render (any other method: the two-view spec's species, broadleaf
# habits of both generators, rendered in the rig its inputs name).
SPECS = {"params": ROOT / "trainers/specs/sketchnet.yaml",
         "sketch-depth": ROOT / "trainers/specs/pix2pix-silhouette.yaml",
         "two-view": ROOT / "reconstruct/specs/two-view.yaml"}
TRAINING_SPECS = ("sketchnet", "pix2pix-silhouette", "pix2pix-trunk")
# Bench-own job seeds: tree i of a method grows from tree_seed(seed, i); checked against the training specs'.
BENCH_SEEDS = {"params": 2304, "sketch-depth": 2300, "two-view": 2301}
OTHER_SEED = 2309  # any other method's
TARGET_S = 2.0
BASELINE = "baseline: same preset"

# The papers' figures beside each metric (seeds-digest section 5); "" where none is published.
PAPER = {
    "depth error, silhouette network": "0.041 (thesis, 4 days GTX 1080 Ti)",
    "depth error, trunk network": "0.032 (thesis)",
    "trunk depth error, up to mirror": "0.127 for a constant 0.5 (bench_depth_bounds)",
    "main skeleton, unit-cube Hausdorff": "0.098 (thesis, trunk nodes, units n.g.)",
    "nodes, unit-cube Hausdorff": "~0.03 (TSN rotation test, one tree)",
    "rotation sweep, unit-cube Hausdorff": "~0.03 (TSN, 72 views, one unseen tree)",
    "surface Hausdorff / height": "TSN HDD: EfficientNet-B7 lowest, values n.g.",
    "species accuracy": "n.g. (bench_train target >= 0.95)",
    "score_overall": "n.g. (TSN tables are images)",
}
# Figures published for one method only (TreeSketchNet's HDD is not the others' reference).
PAPER_METHOD = {"nodes, unit-cube Hausdorff": "params", "surface Hausdorff / height": "params"}
STAGE_PAPER = {
    ("sketch-depth", "trunk recovery (trunk net + trace)"): "0.069-0.083 s (GPU)",
    ("sketch-depth", "silhouette recovery (silhouette net + denoise + crown)"): "0.058-0.072 s (GPU)",
    ("sketch-depth", "growth (field + growth)"): "1.07-1.53 s (i7-7700HQ)",
    ("two-view", "total"): "7 s peach, <= 30 s (2 GHz dual core)",
}


@dataclass
class Truth:
    """One held-out tree: its preset, dictionary, skeleton and mesh, and its views in the method's rig."""

    preset: str
    seed: int
    params: dict
    skeleton: species.Skeleton
    mesh: species.TreeMesh
    views: list[RenderedView]

    @property
    def main_nodes(self) -> np.ndarray:
        return main_branch_nodes(self.skeleton)


def grow_truth(renderer: ViewRenderer, preset: str, seed: int, rig: str, size: int, outputs) -> Truth:
    """A tree as `farm generate` makes it from (preset, tree seed): sample, rebuild, render the rig."""
    sample_rng, render_rng = stage_rngs(seed)
    params = species.sample(preset, sample_rng)
    skeleton, mesh = species.rebuild(params)
    renderer.size = int(size)
    return Truth(preset, seed, params, skeleton, mesh, renderer.render(mesh, skeleton, rig, outputs, render_rng))


FIRST_GUESS = "first guess"


def fit_variants(args) -> list[tuple[str, int]]:
    """(variant, fit budget): the method's first guess (fitting off), then fitted with --fit-evals (if > 0)."""
    return [(FIRST_GUESS, 0)] + ([(f"fitted, {args.fit_evals} evals", args.fit_evals)] if args.fit_evals else [])


def spread(names: list[str], n: int) -> list[str]:
    """n presets spread evenly over `names` (both generators of a mixed list), cycling when n > len(names)."""
    if n <= len(names):
        return [names[int(i)] for i in np.round(np.linspace(0, len(names) - 1, n))]
    return [names[i % len(names)] for i in range(n)]


def drawn_methods() -> list[str]:
    """The registry's methods whose every input is a rendered drawing (`Input.rendered`), in its order."""
    return [name for name, m in METHODS.items() if all(item.rendered is not None for item in m.reads)]


def bench_seed(method: str) -> int:
    return BENCH_SEEDS.get(method, OTHER_SEED)


def seen_azimuths(method: Method) -> list[float]:
    """The azimuths of the views a method's inputs are drawn in (their rig's, `renderers.camera.parse_rig`)."""
    views = {item.rendered.view for item in method.reads}
    return [azimuth for name, azimuth, _ in parse_rig(method.reads[0].rendered.rig).views if name in views]


def check_seeds() -> None:
    taken = {load_spec(ROOT / f"trainers/specs/{name}.yaml").seed: name for name in TRAINING_SPECS}
    taken[load_spec(SPECS["two-view"]).seed] = "two-view"
    for method, seed in {**BENCH_SEEDS, "any other": OTHER_SEED}.items():
        if seed in taken:
            raise SystemExit(f"bench seed {seed} of {method} is the {taken[seed]} spec's: pick another")


# ------------------------------------------------------------------------------------------------ scoring
class Scorer(TreeScorer):
    """`reconstruct.scoring.TreeScorer` of one GT tree, its rows keyed by the metrics' labels (the tables' rows)."""

    def __init__(self, renderer: ViewRenderer, truth: Truth, input_cameras, method: str, surface_samples: int):
        super().__init__(renderer, truth.skeleton, truth.mesh, input_cameras, seen_azimuths(METHODS[method]),
                         surface_samples)
        self.truth = truth

    def __call__(self, skeleton, mesh, main_nodes=None) -> dict[str, float]:
        return {METRICS[k].label: v for k, v in super().__call__(skeleton, mesh, main_nodes).items()}


def baseline_tree(truth: Truth, job_seed: int, index: int, n_trees: int):
    """Another tree of the true preset (a tree seed outside the bench's plan): the prior a reconstruction beats."""
    params = species.sample(truth.preset, stage_rngs(tree_seed(job_seed, n_trees + index))[0])
    skeleton, mesh = species.rebuild(params)
    return params, skeleton, mesh, main_branch_nodes(skeleton)


def sheet_cells(renderer, scorer: Scorer, inputs: dict, skeleton, mesh) -> list:
    truth, front, unseen = scorer.truth, scorer.cameras["input"][0], scorer.cameras["unseen"][0]
    return [*inputs.items(), ("GT, input view", depth_picture(renderer, truth.mesh, truth.skeleton, front)),
            ("reconstruction", depth_picture(renderer, mesh, skeleton, front)),
            (f"GT, {unseen.name}", depth_picture(renderer, truth.mesh, truth.skeleton, unseen)),
            ("reconstruction", depth_picture(renderer, mesh, skeleton, unseen))]


# ------------------------------------------------------------------------------------------------ methods
class Run:
    """What one method collects: per-variant metric rows, per-stage seconds, failures, contact sheet rows."""

    def __init__(self, method: str):
        self.method = method
        self.rows: dict[str, list[dict]] = {}
        self.stages: dict[str, list[float]] = {}
        self.failed: dict[str, list[str]] = {}
        self.sheet: list = []
        self.pooled: dict[str, dict[str, float | str]] = {}  # metric pooled over trees -> {variant: value}

    def add(self, variant: str, row: dict) -> None:
        self.rows.setdefault(variant, []).append(row)

    def time(self, timings: dict, variant: str | None = None) -> None:
        """Seconds per stage; a variant other than the first fit's (`fit_variants`) keys its stages by name."""
        for stage, seconds in timings.items():
            key = stage if variant in (None, FIRST_GUESS) else f"{stage}, {variant}"
            self.stages.setdefault(key, []).append(float(seconds))

    def fail(self, variant: str, truth: Truth, error: TreefarmError) -> None:
        self.failed.setdefault(variant, []).append(f"{truth.preset} seed {truth.seed}: {error}")


def run_params(renderer, args, run: Run) -> None:
    net = predictor("sketchnet", args.models)
    spec = load_spec(SPECS["params"])
    presets = spread(list(spec.species), args.trees)
    predicted: dict[str, list[dict]] = {}
    true, baseline = [], []
    for i, preset in enumerate(presets):
        truth = grow_truth(renderer, preset, tree_seed(BENCH_SEEDS["params"], i), spec.render.rig, net.input_size,
                           ["sketch_tsn"])
        front = truth.views[0]
        scorer = Scorer(renderer, truth, [front.camera], "params", args.surface_samples)
        # Like the other methods, the tree is grown at the true height (a sketch has no scale); the network's
        # own guess of the size is scored on its own row.
        guessed = reconstruct.from_params(front.images["sketch_tsn"], net=net, fit_evals=0)
        for variant, evals in fit_variants(args):
            result = reconstruct.from_params(front.images["sketch_tsn"], net=net, height=truth.skeleton.height,
                                             fit_evals=evals, renderer=renderer)
            run.time(result.timings, variant)
            row = scorer(result.skeleton, result.mesh)
            row["species accuracy"] = float(result.params.get("species") == truth.params["species"])
            row["height rel. error, size guessed"] = metrics.height_crown_errors(guessed.skeleton,
                                                                                 truth.skeleton)["height_rel_error"]
            run.add(variant, row)
            predicted.setdefault(variant, []).append(result.params)
        true.append(truth.params)
        b_params, b_skeleton, b_mesh, _ = baseline_tree(truth, BENCH_SEEDS["params"], i, args.trees)
        run.add(BASELINE, {**scorer(b_skeleton, b_mesh), "species accuracy": 1.0,
                           "height rel. error, size guessed": metrics.height_crown_errors(
                               b_skeleton, truth.skeleton)["height_rel_error"]})
        baseline.append(b_params)
        if i < args.sheet_trees:
            run.sheet.append((f"params {preset}", sheet_cells(renderer, scorer, {"sketch_tsn": front.images["sketch_tsn"]},
                                                              result.skeleton, result.mesh)))
        print(f"  params {i + 1}/{len(presets)} {preset}: {result.timings['total']:.2f} s", flush=True)
    for variant, guesses in (*predicted.items(), (BASELINE, baseline)):
        for name, value in metrics.parameter_scores(net.codec, guesses, true).items():
            run.pooled.setdefault(f"{name} (pooled)", {})[variant] = float(value)
    sweep(renderer, net, args, presets, run)


def sweep(renderer, net, args, presets: list[str], run: Run) -> None:
    """TreeSketchNet's rotation test: the unit-cube Hausdorff of the tree read from each view of orbit:N:10."""
    rig = f"orbit:{args.sweep_views}:10"
    per_tree: dict[str, list[list[float]]] = {variant: [] for variant, _ in fit_variants(args)}
    for i, preset in enumerate(presets[:args.sweep_trees]):
        truth = grow_truth(renderer, preset, tree_seed(BENCH_SEEDS["params"], i), rig, net.input_size, ["sketch_tsn"])
        for variant, evals in fit_variants(args):
            per_tree[variant].append([metrics.unit_cube_hausdorff(reconstruct.from_params(
                v.images["sketch_tsn"], net=net, fit_evals=evals, renderer=renderer).skeleton, truth.skeleton)
                for v in truth.views])
        print(f"  sweep {i + 1}/{args.sweep_trees} {preset}: {len(truth.views)} views, mean "
              + ", ".join(f"{v} {np.mean(d[-1]):.3f}" for v, d in per_tree.items()), flush=True)
    for variant, distances in per_tree.items():
        if not distances:
            continue
        everything = np.concatenate(distances)
        for name, value in (("rotation sweep, unit-cube Hausdorff", float(everything.mean())),
                            ("  median", float(np.median(everything))),
                            ("  worst view", float(everything.max())), ("  best view", float(everything.min())),
                            ("  trees x views", f"{len(distances)} x {args.sweep_views} ({rig})")):
            run.pooled.setdefault(name, {})[variant] = value


def run_sketch_depth(renderer, args, run: Run) -> None:
    silhouette_net = predictor("pix2pix-silhouette", args.models)
    trunk_net = predictor("pix2pix-trunk", args.models)
    spec = load_spec(SPECS["sketch-depth"])
    presets = spread(list(spec.species), args.trees)
    outputs = ["sketch_edges", "trunk_strokes", "silhouette_envelope", "trunk_depth"]
    for i, preset in enumerate(presets):
        seed = tree_seed(BENCH_SEEDS["sketch-depth"], i)
        truth = grow_truth(renderer, preset, seed, spec.render.rig, spec.render.size, outputs)
        front = truth.views[0]
        scorer = Scorer(renderer, truth, [front.camera], "sketch-depth", args.surface_samples)
        sil_error, sil_s = network_depth_error(silhouette_net, "silhouette", front.images)
        trunk_error, trunk_s = network_depth_error(trunk_net, "trunk", front.images)
        trunk_mirror = network_depth_error(trunk_net, "trunk", front.images, up_to_mirror=True)[0]
        height = truth.skeleton.height
        for variant, evals in fit_variants(args):
            try:
                result = reconstruct.from_sketch(front.images["sketch_edges"], front.images["trunk_strokes"],
                                                 silhouette_net=silhouette_net, trunk_net=trunk_net,
                                                 species=args.species, height=height, rng=np.random.default_rng(seed),
                                                 fit_evals=evals, renderer=renderer)
            except TreefarmError as error:
                run.fail(variant, truth, error)
                continue
            t = result.timings
            run.time({"silhouette network": sil_s, "trunk network": trunk_s, **t,
                      "trunk recovery (trunk net + trace)": trunk_s + t["trunk"],
                      "silhouette recovery (silhouette net + denoise + crown)": sil_s + t["denoise"] + t["crown"],
                      "growth (field + growth)": t["field"] + t["growth"]}, variant)
            run.add(variant, {"depth error, silhouette network": sil_error, "depth error, trunk network": trunk_error,
                              METRICS["depth_error_trunk_mirror"].label: trunk_mirror,
                              **scorer(result.skeleton, result.mesh, result.maps["main_skeleton"])})
            if i < args.sheet_trees and evals == args.fit_evals:
                inputs = {"sketch_edges": front.images["sketch_edges"], "trunk_strokes": front.images["trunk_strokes"]}
                run.sheet.append((f"sketch-depth {preset}",
                                  sheet_cells(renderer, scorer, inputs, result.skeleton, result.mesh)))
        try:
            oracle = reconstruct.from_maps(front.images["silhouette_envelope"], front.images["trunk_depth"],
                                           front.images["trunk_strokes"], front.camera,
                                           species=args.species or DEFAULT_SPECIES,
                                           height=height, rng=np.random.default_rng(seed))
            run.add("GT maps", scorer(oracle.skeleton, oracle.mesh, oracle.maps["main_skeleton"]))
        except TreefarmError as error:
            run.fail("GT maps", truth, error)
        _, b_skeleton, b_mesh, b_main = baseline_tree(truth, BENCH_SEEDS["sketch-depth"], i, args.trees)
        run.add(BASELINE, scorer(b_skeleton, b_mesh, b_main))
        print(f"  sketch-depth {i + 1}/{len(presets)} {preset}", flush=True)


def run_two_view(renderer, args, run: Run) -> None:
    spec = load_spec(SPECS["two-view"])
    presets = spread(list(spec.species), args.trees)
    for i, preset in enumerate(presets):
        seed = tree_seed(BENCH_SEEDS["two-view"], i)
        truth = grow_truth(renderer, preset, seed, spec.render.rig, spec.render.size, spec.render.outputs)
        front, side = truth.views
        scorer = Scorer(renderer, truth, [front.camera, side.camera], "two-view", args.surface_samples)
        drawn_height = float(truth.main_nodes[:, 2].max())
        for (stroke, output), (fit, evals) in itertools.product(
                (("1-px lines", "sketch_strokes"), ("brush", "sketch_strokes_brush")), fit_variants(args)):
            variant = f"{stroke}, {fit}"
            start = time.perf_counter()
            try:
                result = reconstruct.two_view(front.images[output], side.images[output], height=drawn_height,
                                              rng=np.random.default_rng(seed), brush=stroke == "brush",
                                              fit_evals=evals)
            except TreefarmError as error:
                run.fail(variant, truth, error)
                continue
            total = time.perf_counter() - start
            if stroke == "1-px lines":
                run.time({**result.timings, "total": total}, fit)
            else:
                run.time({"total, brush": total}, fit)
            run.add(variant, scorer(result.skeleton, result.mesh, result.maps["main_skeleton"]))
            if i < args.sheet_trees and stroke == "1-px lines" and evals == args.fit_evals:
                inputs = {"front": front.images[output], "side": side.images[output]}
                run.sheet.append((f"two-view {preset}", sheet_cells(renderer, scorer, inputs, result.skeleton,
                                                                    result.mesh)))
        _, b_skeleton, b_mesh, b_main = baseline_tree(truth, BENCH_SEEDS["two-view"], i, args.trees)
        run.add(BASELINE, scorer(b_skeleton, b_mesh, b_main))
        print(f"  two-view {i + 1}/{len(presets)} {preset}", flush=True)


def run_drawn(renderer, args, run: Run) -> None:
    """Any other drawing method of the registry: trees of the two-view spec's species rendered in the rig its
    inputs name, grown at the true height with its networks, beside the same-preset baseline."""
    method = METHODS[run.method]
    rig = method.reads[0].rendered.rig
    views = list(dict.fromkeys(item.rendered.view for item in method.reads))
    outputs = list(dict.fromkeys(item.rendered.output for item in method.reads))
    nets = {task: predictor(task, args.models) for task in method.models}
    spec = load_spec(SPECS["two-view"])
    presets = spread(list(spec.species), args.trees)
    for i, preset in enumerate(presets):
        seed = tree_seed(OTHER_SEED, i)
        truth = grow_truth(renderer, preset, seed, rig, spec.render.size, outputs)
        by_name = {view.name: view for view in truth.views}
        inputs = {item.name: by_name[item.rendered.view].images[item.rendered.output] for item in method.reads}
        scorer = Scorer(renderer, truth, [by_name[v].camera for v in views], run.method, args.surface_samples)
        try:
            result = method.run(inputs, RunOptions(seed=seed, height=truth.skeleton.height, nets=nets))
        except TreefarmError as error:
            run.fail(run.method, truth, error)
        else:
            run.time(result.timings)
            run.add(run.method, scorer(result.skeleton, result.mesh, result.maps.get("main_skeleton")))
            if i < args.sheet_trees:
                run.sheet.append((f"{run.method} {preset}", sheet_cells(renderer, scorer, inputs, result.skeleton,
                                                                        result.mesh)))
        _, b_skeleton, b_mesh, b_main = baseline_tree(truth, OTHER_SEED, i, args.trees)
        run.add(BASELINE, scorer(b_skeleton, b_mesh, b_main))
        print(f"  {run.method} {i + 1}/{len(presets)} {preset}", flush=True)


RUNNERS = {"params": run_params, "sketch-depth": run_sketch_depth, "two-view": run_two_view}


# ------------------------------------------------------------------------------------------------ tables
def number(value) -> str:
    return f"{value:.3f}" if isinstance(value, float) else value


def metric_table(bench: Benchmark, run: Run) -> None:
    """The method's metrics, mean over trees per variant, beside the papers' figures; failures as notes."""
    variants = list(run.rows)
    names: list[str] = []
    for rows in run.rows.values():
        for row in rows:
            names += [k for k in row if k not in names]
    table = []
    for name in names:
        cells = []
        for variant in variants:
            values = [r[name] for r in run.rows[variant] if name in r and np.isfinite(r[name])]
            cells.append(float(np.mean(values)) if values else "-")
        paper = PAPER.get(name, "") if PAPER_METHOD.get(name, run.method) == run.method else ""
        table.append([name, *map(number, cells), paper])
    for name, by_variant in run.pooled.items():
        table.append([name, *[number(by_variant.get(v, "")) for v in variants],
                      PAPER.get(name.removesuffix(" (pooled)"), "")])
    counts = [f"{len(run.rows[v])} trees" for v in variants]
    bench.table(f"{run.method}: quality on held-out trees (job seed {bench_seed(run.method)})",
                ["metric (mean over trees)", *[f"{v} ({c})" for v, c in zip(variants, counts)], "paper"], table,
                notes=[f"{variant}: {len(messages)} failed, first: {messages[0]}"
                       for variant, messages in run.failed.items()])


def stage_table(bench: Benchmark, run: Run) -> None:
    rows = []
    for stage, seconds in run.stages.items():
        target = ""
        if stage.startswith("total"):
            target = "yes" if np.mean(seconds) < TARGET_S else "no"
        rows.append([stage, f"{np.mean(seconds):.3f}", f"{np.max(seconds):.3f}", target,
                     STAGE_PAPER.get((run.method, stage), "")])
    bench.table(f"{run.method}: seconds per tree and stage", ["stage", "mean s", "max s", f"< {TARGET_S:.0f} s",
                                                                 "paper"], rows)


def headline_figures(bench: Benchmark, run: Run, args) -> None:
    """The method's crown IoU from unseen views (beside the same-preset baseline's) and its seconds per tree."""
    label = METRICS["crown_iou_unseen"].label
    # The method as a user runs it: its fitted variant where it ran (the first: two-view's 1-px lines), else the
    # first that is neither the baseline nor an oracle.
    fitted = [v for v in run.rows if "fitted" in v]
    variant = fitted[0] if fitted else next((v for v in run.rows if v != BASELINE), None)

    def mean(rows: list[dict]) -> float:
        return float(np.mean([r[label] for r in rows if np.isfinite(r.get(label, np.nan))] or [np.nan]))

    if variant is not None:
        bench.figure(f"{run.method}: {label}", mean(run.rows[variant]), "",
                     f"another tree of the preset: {mean(run.rows.get(BASELINE, [])):.2f}")
    fit = next((f for f, _ in fit_variants(args) if f in (variant or "")), None)
    total = f"total, {fit}" if f"total, {fit}" in run.stages else "total"
    if total in run.stages:
        bench.figure(f"{run.method}: seconds per tree", float(np.mean(run.stages[total])), "s",
                     f"target < {TARGET_S:.0f} s")


def main(argv=None) -> None:
    parser = arguments(__doc__)
    parser.add_argument("--trees", type=int, default=12, help="held-out trees per method")
    drawn = drawn_methods()
    parser.add_argument("--methods", default=",".join(drawn), help="comma separated: " + ", ".join(drawn))
    parser.add_argument("--sweep-trees", type=int, default=3, help="trees of the params rotation sweep")
    parser.add_argument("--sweep-views", type=int, default=72, help="views of the sweep (rig orbit:N:10)")
    parser.add_argument("--surface-samples", type=int, default=metrics.SURFACE_SAMPLES,
                        help="surface samples per mesh (0: skip the surface distances)")
    parser.add_argument("--sheet-trees", type=int, default=3, help="trees per method on the contact sheet")
    parser.add_argument("--species", default=None, help="sketch-depth growth preset (default the method's)")
    parser.add_argument("--fit-evals", type=int, default=DEFAULT_FIT_EVALS,
                        help="the fit's budget (a variant beside the first guess; 0: first guess only)")
    parser.add_argument("--models", default=None, help="model registry URI (default: the shipped models/)")
    parser.add_argument("--out", type=Path, default=ROOT / "out" / "bench_reconstruct")
    args = parser.parse_args(argv)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in methods if m not in drawn]
    if unknown or args.trees < 1 or not 1 <= args.sweep_views <= 360 or args.fit_evals < 0:
        parser.error(f"methods {unknown} unknown (allowed {', '.join(drawn)}), or --trees < 1, or --sweep-views "
                     f"outside [1, 360], or --fit-evals < 0")
    check_seeds()
    bench = Benchmark("reconstruct", "Reconstruction from drawings: quality on held-out trees and seconds per tree",
                      args)
    renderer = ViewRenderer(256)
    runs = []
    try:
        for method in methods:
            run = Run(method)
            RUNNERS.get(method, run_drawn)(renderer, args, run)
            runs.append(run)
    finally:
        renderer.close()
    sheet = []
    for run in runs:
        metric_table(bench, run)
        stage_table(bench, run)
        sheet += run.sheet
    print()
    for run in runs:
        headline_figures(bench, run, args)
    if sheet:
        path = write_contact_sheet(args.out / "reconstructions.png", sheet)
        bench.note(f"contact sheet: {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    bench.write()


if __name__ == "__main__":
    main()
