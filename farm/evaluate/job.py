"""The evaluation job: every method on the held-out trees of each dataset (and on real inputs), as Ray tasks.

Plan: for each dataset, its trees in the trainers' held-out part (`trainers.data.split_part`, the one split rule:
a hash of the spec digest and tree id; `part="all"` takes every tree, for a dataset no model trained on), capped at
`trees` per dataset and picked across its species (`pick_across_species`); for each method the dataset serves
(its rig and outputs hold the method's `Needs`), one unit per tree. A method a dataset cannot serve is skipped with
a line saying why.

Report folder (docs/evaluation.md): `evaluation.json` (the job: datasets, methods, settings, how trees are picked;
written first, a rerun with another job is refused), `rows/METHOD/KEY.parquet` (one finished unit; written last
and atomically, so a killed job resumes without repeating finished trees), `panels/METHOD/KEY.png` (input,
reconstruction and ground truth), then `metrics.parquet` (every row), `sweep.parquet`, `summary.md` and the PNG
plots (`farm.evaluate.report`).
A method that fails on a tree records the error in its row (status "failed", or "error" with the traceback for a
bug) and the job goes on.
"""
from __future__ import annotations

import json
import os
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from farm.dataset import DatasetError, read_columns, read_manifest
from farm.pipeline import ray_connection
from reconstruct.fit_budget import check_fit_evals
from reconstruct.networks import predictor
from renderers import rig_parts
from renderers.camera import parse_rig
from renderers.contact_sheet import contact_sheet
from species.errors import TreefarmError
from species.meshing.png import png_bytes
from trainers.registry import check_registry_exists

from .inputs import input_units, run_input
from .methods import METHODS, EvalSettings, run_method
from .report import write_report
from .sweep import run_sweep
from .units import (FORMAT, ID_COLUMNS, JOB_FILE, METRICS_FILE, PANELS, PARTS, ROWS, EvaluationError, Unit,
                    load_tree, worker_context, write_atomically)

__all__ = ["EvaluationError", "Unit", "DatasetInfo", "EvaluationPlan", "plan_evaluation", "run_evaluation",
           "JOB_FILE", "ROWS", "PANELS", "METRICS_FILE", "PARTS", "read_rows", "serves", "ID_COLUMNS",
           "load_tree", "evaluation_data_spec", "pick_across_species", "TREE_PICK"]

# How `--trees N` picks a dataset's trees, recorded in evaluation.json: a report folder whose trees were picked
# another way (spread evenly over the list, before issue 48) is not resumed with these picks mixed in.
TREE_PICK = "across species"

@dataclass(frozen=True)
class DatasetInfo:
    path: str
    spec_digest: str
    name: str
    rig: str
    outputs: tuple[str, ...]
    held_out: tuple[str, ...]  # tree ids, plan order
    held_out_species: tuple[str, ...] = ()  # the species of each held-out tree


@dataclass
class EvaluationPlan:
    datasets: list[DatasetInfo]
    methods: list[str]
    units: list[Unit]
    skipped: list[str] = field(default_factory=list)
    record: dict = field(default_factory=dict)
    picked: dict[str, dict[str, int]] = field(default_factory=dict)  # dataset path -> species -> trees picked


def _view_names(rig: str) -> dict[str, list[str]]:
    """rig part (":jitter" dropped) -> the dataset's view names in it, as `renderers.make_rig` names them."""

    parts = rig_parts(rig)
    out = {}
    for part in parts:
        base = part.removesuffix(":jitter")
        names = [name for name, _, _ in parse_rig(part).views]
        out[base] = [f"{part}/{n}" if len(parts) > 1 else n for n in names]
    return out


def serves(method: str, rig: str, outputs: Sequence[str]) -> tuple[tuple[tuple[str, str], ...] | None, str]:
    """((method view, dataset view) pairs, "") when a dataset of `rig` storing `outputs` serves the method;
    (None, why not) otherwise."""
    needs = METHODS[method].needs
    if needs.rig is None:
        return (), ""
    names = _view_names(rig)
    if needs.rig not in names:
        return None, f"its rig {rig!r} has no {needs.rig!r} views"
    missing = [o for o in needs.outputs if o not in outputs]
    if missing:
        return None, f"its views lack {', '.join(missing)} (stored: {', '.join(outputs) or 'none'})"
    pairs = []
    for view in needs.views:
        matches = [n for n in names[needs.rig] if n.rsplit("/", 1)[-1] == view]
        pairs.append((view, matches[0]))
    return tuple(pairs), ""


def _open_dataset(path: str, part: str) -> DatasetInfo:
    from trainers.data import split_part  # here: trainers.data imports torch

    try:
        manifest = read_manifest(path)
    except DatasetError as error:
        raise EvaluationError(f"--data {path}: {error}") from None
    trees = read_columns(path, "trees", ["tree_id", "index", "species", "error"]).to_pylist()
    ids = [(r["index"], r["tree_id"], r["species"]) for r in trees if r["error"] is None]
    digest = manifest["spec_digest"]
    kept = [(tree, name) for _, tree, name in sorted(ids) if part == "all" or split_part((digest, tree)) == part]
    render = manifest["job"].get("render", {})
    return DatasetInfo(str(path), digest, manifest["job"].get("name", Path(path).name), render.get("rig", ""),
                       tuple(render.get("outputs", ())), tuple(t for t, _ in kept), tuple(n for _, n in kept))


def _spread(items: Sequence, n: int) -> list:
    if n >= len(items):
        return list(items)
    return [items[int(i)] for i in np.round(np.linspace(0, len(items) - 1, n))]


def pick_across_species(trees: Sequence[str], species_of_trees: Sequence[str], n: int | None) -> list[str]:
    """At most `n` of `trees` (in their order), as many of each species as the others where a species has that
    many: a round over the species (the larger groups first, then by name) takes one tree each until `n` are
    taken, and each species' trees are spread evenly over its own list. A dataset's species are interleaved, so
    spreading over the whole list can fall on one or two species."""
    if n is None or n >= len(trees):
        return list(trees)
    positions: dict[str, list[int]] = {}
    for position, name in enumerate(species_of_trees):
        positions.setdefault(name, []).append(position)
    order = sorted(positions, key=lambda name: (-len(positions[name]), name))
    quota = dict.fromkeys(order, 0)
    left = n
    while left:
        for name in order:
            if left and quota[name] < len(positions[name]):
                quota[name] += 1
                left -= 1
    chosen = sorted(p for name in order for p in _spread(positions[name], quota[name]))
    return [trees[p] for p in chosen]


def plan_evaluation(data: Sequence[str], methods: Sequence[str], *, trees: int | None = None, part: str = "test",
                    inputs: str | None = None, settings: EvalSettings = EvalSettings(),
                    models: str | None = None) -> EvaluationPlan:
    """The units to run; EvaluationError for an unknown method or part, a dataset that cannot be read, or a job
    with nothing to evaluate, FitError for a fit budget that is not a count. Writes nothing."""
    methods = list(dict.fromkeys(methods))
    unknown = [m for m in methods if m not in METHODS]
    if unknown or not methods:
        raise EvaluationError(f"--methods {','.join(methods)}: unknown {', '.join(unknown) or 'none given'}; allowed "
                              f"{', '.join(METHODS)} (comma-separated)")
    if part not in PARTS:
        raise EvaluationError(f"--part {part!r} is invalid: allowed {', '.join(PARTS)}")
    if trees is not None and trees < 1:
        raise EvaluationError(f"--trees {trees} is invalid: allowed an integer >= 1")
    check_fit_evals(settings.fit_evals)
    if not data and inputs is None:
        raise EvaluationError("nothing to evaluate: pass --data DIR [DIR...] and/or --inputs DIR")
    datasets = [_open_dataset(path, part) for path in data]
    units, skipped, picked = [], [], {}
    for info in datasets:
        if not info.held_out:
            raise EvaluationError(f"--data {info.path} has no {'usable' if part == 'all' else part + ' (held-out)'} "
                                  f"trees: allowed a dataset with at least one"
                                  f"{'' if part == 'all' else ' (or --part all for a dataset no model trained on)'}")
        chosen = pick_across_species(info.held_out, info.held_out_species, trees)
        species_of = dict(zip(info.held_out, info.held_out_species))
        picked[info.path] = {}
        for tree in chosen:
            picked[info.path][species_of[tree]] = picked[info.path].get(species_of[tree], 0) + 1
        for method in methods:
            pairs, why = serves(method, info.rig, info.outputs)
            if pairs is None:
                skipped.append(f"{method}: skipped for {info.path}: {why} (farm evaluate --print-data-spec "
                               "prints a spec that serves every method)")
                continue
            units += [Unit(method, "held-out", info.path, info.spec_digest, tree, pairs) for tree in chosen]
    if inputs is not None:
        input_units_, input_skipped = input_units(inputs, methods)
        units += input_units_
        skipped += input_skipped
    if not units:
        raise EvaluationError("nothing to evaluate: " + ("; ".join(skipped) if skipped else "no trees"))
    record = {"format": FORMAT, "methods": methods, "part": part, "trees": trees, "pick": TREE_PICK, "inputs": inputs,
              "models": models, "settings": asdict(settings),
              "datasets": [{"path": d.path, "spec_digest": d.spec_digest, "name": d.name, "rig": d.rig}
                           for d in datasets]}
    return EvaluationPlan(datasets, methods, units, skipped, record, picked)


def _stage_column(stage: str) -> str:
    return "seconds_" + "".join(c if c.isalnum() else "_" for c in stage.lower()).strip("_")


def evaluate_unit(unit: Unit, report_dir: str, models: str | None, settings: EvalSettings) -> dict:
    """Run one unit, write its panel and then its row file; returns the row."""
    import pyarrow as pa
    import pyarrow.parquet as pq


    report = Path(report_dir)
    row = {"method": unit.method, "source": unit.source, "dataset": unit.dataset, "spec_digest": unit.spec_digest,
           "tree_id": unit.tree_id, "species": None, "status": "ok", "error": None}
    started = time.perf_counter()
    try:
        ctx = worker_context(models, settings)
        if unit.source == "input":
            result, row["species"] = run_input(unit, ctx)
        else:
            tree = load_tree(unit)
            row["species"] = tree.species
            result = run_method(unit.method, tree, ctx)
        row.update(result.metrics)
        row.update({_stage_column(k): float(v) for k, v in result.timings.items()})
        row["models"] = json.dumps(result.models, sort_keys=True)
        panel = Path(PANELS) / unit.method / f"{unit.key}.png"
        title = f"{unit.method}: {row['species'] or ''} {Path(unit.tree_id).name}"
        write_atomically(report / panel, png_bytes(contact_sheet([(title, result.cells)], cell=192), 6))
        row["panel"] = str(panel)
    except TreefarmError as error:
        row.update(status="failed", error=str(error).strip().splitlines()[0] if str(error).strip() else
                   type(error).__name__)
    except Exception:  # a bug: recorded with its traceback, the job goes on, and the command exits 1
        row.update(status="error", error=traceback.format_exc())
    row["seconds_unit"] = time.perf_counter() - started
    table = pa.Table.from_pylist([row])
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    write_atomically(report / ROWS / unit.method / f"{unit.key}.parquet", sink.getvalue().to_pybytes())
    return row


# ------------------------------------------------------------------------------------------------ the job
def _check_report_dir(report: Path, record: dict) -> None:
    job = report / JOB_FILE
    if job.exists():
        try:
            old = json.loads(job.read_text())
        except ValueError:
            old = None
        if isinstance(old, dict) and "pick" not in old and {**old, "pick": record["pick"]} == record:
            if record["trees"] is not None:
                raise EvaluationError(f"--out {report} holds this evaluation with its trees picked another way (an "
                                      f"older treefarm spread --trees {record['trees']} over the list; now "
                                      f"{TREE_PICK}): allowed a new folder")
            return  # without --trees every tree is taken: how they are picked makes no difference
        if old != record:
            raise EvaluationError(f"--out {report} holds another evaluation ({JOB_FILE} differs: other datasets, "
                                  "methods or settings): allowed a new folder, or this job's own folder to resume")
    elif report.exists() and any(report.iterdir()):
        raise EvaluationError(f"--out {report} is not empty and holds no {JOB_FILE}: allowed a new or empty folder")


def read_rows(report_dir: str | Path, units: Sequence[Unit] | None = None):
    """The finished rows (a pandas DataFrame) of a report folder, of `units` only when given."""
    import pandas as pd
    import pyarrow.parquet as pq

    report = Path(report_dir)
    if units is None:
        files = sorted((report / ROWS).glob("*/*.parquet"))
    else:
        files = [report / ROWS / u.method / f"{u.key}.parquet" for u in units]
        files = [f for f in files if f.exists()]
    frames = [pq.read_table(f).to_pandas() for f in files]
    if not frames:
        return pd.DataFrame(columns=ID_COLUMNS)
    frame = pd.concat(frames, ignore_index=True)
    metrics = sorted(c for c in frame.columns if c not in ID_COLUMNS and not c.startswith("seconds_")
                     and c not in ("models", "panel"))
    seconds = sorted(c for c in frame.columns if c.startswith("seconds_"))
    frame = frame[[*ID_COLUMNS, *metrics, *seconds, *[c for c in ("models", "panel") if c in frame.columns]]]
    return frame.sort_values(["method", "source", "dataset", "tree_id"], kind="stable").reset_index(drop=True)


def _check_models(plan: EvaluationPlan, models: str | None) -> dict[str, str]:
    """Load each network the plan's methods use once, before anything is written: a models URI without one is
    one line (EvaluationError). Returns task -> the model's source."""

    tasks = sorted({task for m in {u.method for u in plan.units} for task in METHODS[m].models})
    sources = {}
    if tasks and models is not None:
        try:
            check_registry_exists(models)
        except TreefarmError as error:
            raise EvaluationError(str(error)) from None
    for task in tasks:
        try:
            sources[task] = predictor(task, models).source
        except TreefarmError as error:
            raise EvaluationError(f"--models {models or '(shipped models/)'}: {error}") from None
    return sources


def run_evaluation(plan: EvaluationPlan, out: str | Path, *, models: str | None = None,
                   settings: EvalSettings = EvalSettings(), workers: int | None = None, address: str | None = None,
                   sweep_step: float | None = 5.0, progress: bool = True) -> dict:
    """Run the plan's pending units on Ray, then write metrics.parquet, the sweep, summary.md and the plots.
    Returns {"rows": DataFrame, "done_before": n, "ran": n, "models": sources, "report": paths, "sweep": table,
    "seconds": {"trees": the Ray phase (sweep included), "total": with the report}}."""
    import ray
    from tqdm import tqdm


    report = Path(out)
    sources = _check_models(plan, models)
    _check_report_dir(report, plan.record)
    report.mkdir(parents=True, exist_ok=True)
    if not (report / JOB_FILE).exists():
        write_atomically(report / JOB_FILE, json.dumps(plan.record, indent=1, sort_keys=True).encode())
    pending = [u for u in plan.units if not (report / ROWS / u.method / f"{u.key}.parquet").exists()]
    done_before = len(plan.units) - len(pending)
    limit = max(1, workers or os.cpu_count() or 1)
    started = time.perf_counter()
    with ray_connection(address, workers, log_to_driver=False):
        task = ray.remote(num_cpus=1, max_retries=2)(evaluate_unit)
        queue, running = list(pending), []
        with tqdm(total=len(plan.units), initial=done_before, desc="evaluate", unit="tree", disable=not progress) as bar:
            while queue or running:
                while queue and len(running) < limit:  # at most `workers` trees in flight
                    running.append(task.remote(queue.pop(0), str(report), models, settings))
                done, running = ray.wait(running, num_returns=1)
                row = ray.get(done[0])
                bar.set_postfix_str(f"{row['method']} {row['status']}", refresh=False)
                bar.update(1)
        sweep = None
        if sweep_step:
            sweep = run_sweep(plan, report, models, settings, sweep_step)
    trees_seconds = time.perf_counter() - started
    rows = read_rows(report, plan.units)
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pandas(rows, preserve_index=False), sink)
    write_atomically(report / METRICS_FILE, sink.getvalue().to_pybytes())
    paths = write_report(report, rows, plan, sources, models, sweep)
    return {"rows": rows, "done_before": done_before, "ran": len(pending), "models": sources, "report": paths,
            "sweep": sweep, "seconds": {"trees": trees_seconds, "total": time.perf_counter() - started}}


def evaluation_data_spec(trees: int = 24, seed: int = 2500) -> str:
    """A job spec (YAML) whose dataset serves every method: the three sketch rigs joined ("+") and every output a
    method reads, Weber-Penn and colonization species alike, on a seed of its own (no model trained on it)."""
    rigs = "+".join(dict.fromkeys(m.needs.rig for m in METHODS.values() if m.needs.rig))
    outputs = list(dict.fromkeys(o for m in METHODS.values() for o in (*m.needs.outputs, *m.needs.optional)))
    return "\n".join([
        "# An evaluation dataset (`farm evaluate --print-data-spec`): every method's views of the same trees.",
        "# Generate: farm generate eval.yaml --out data/eval; evaluate: farm evaluate --data data/eval --part all",
        "# (its spec digest is its own: no model trained on these trees, so every tree is held out).",
        "# Rigs: tsn4 (params: sketch_tsn), two-view (sketch-depth: sketch_edges, trunk_strokes and the GT depth",
        "# maps), two-view:shared (two-view: sketch_strokes); the cloud and photos methods need only the trees.",
        "name: evaluation", f"seed: {seed}", f"trees: {trees}", "species:",
        *[f"  {name}: 1" for name in ("maple", "black_oak", "cherry", "sassafras", "sc_round_maple", "sc_broad_oak",
                                      "sc_open_fruit_tree", "sc_vase_elm")],
        "render:", f"  rig: {rigs}", "  size: 256", f"  outputs: [{', '.join(outputs)}]",
        "store_glb: false", "shard_size: 8", ""])
