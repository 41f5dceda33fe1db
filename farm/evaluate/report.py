"""The evaluation report: summary.md (the trees per species; per metric and method, median and interquartile
range; the papers' figures, the models' registered scores, the machine and versions) and the PNG plots (metric
distributions per method and per species, a gallery of the best, median and worst trees per method, the rotation
sweep).

Plots are drawn with matplotlib's Agg backend, metadata stripped, so the same rows give the same bytes.
"""
from __future__ import annotations

import json
import platform
import textwrap
from pathlib import Path

import numpy as np

from farm.dataset import read_image
from farm.dataset.manifest import code_version
from farm.table import format_table
from species.meshing.png import png_bytes
from trainers.registry import open_registry
from trainers.tasks import get_task

from .units import ID_COLUMNS, write_atomically

# reconstruct.scoring and trainers.models are imported where used: both packages import torch.

__all__ = ["write_report", "metric_columns", "summary_table", "registered_scores", "GALLERY_METRIC", "SUMMARY_FILE"]

SUMMARY_FILE = "summary.md"
# What ranks a method's trees for its gallery (best, median, worst): the first of these its rows have.
GALLERY_METRIC = ("crown_iou_unseen", "cloud_fit_10cm", "silhouette_iou_input",
                  "param_score", "species_correct")
# The registered held-out figures worth a line in the summary, per trained task.
_REGISTERED = {"sketchnet": ("score_overall", "accuracy_species"), "pix2pix-silhouette": ("depth_error",),
               "pix2pix-trunk": ("depth_error",)}
# The metrics the per-species plot shows (one panel each; every metric is in the per-method plot).
HEADLINE = ("crown_iou_unseen", "node_chamfer", "surface_chamfer", "skeleton_f1_auc", "height_rel_error",
            "cloud_fit_10cm", "param_score", "silhouette_iou_input")
_PACKAGES = ("numpy", "scipy", "trimesh", "pyarrow", "ray", "onnxruntime", "pycolmap", "torch", "mlflow-skinny")


def metric_columns(rows) -> list[str]:
    """The metric columns of a rows frame (numbers, not ids, timings, models or panels) in METRICS' order."""
    from reconstruct.scoring import METRICS

    present = [c for c in rows.columns if c not in ID_COLUMNS and not c.startswith("seconds_")
               and c not in ("models", "panel")]
    return [m for m in METRICS if m in present] + sorted(set(present) - set(METRICS))


def _quartiles(values: np.ndarray) -> tuple[float, float, float]:
    q25, q50, q75 = np.percentile(values, [25, 50, 75])
    return float(q50), float(q25), float(q75)


def summary_table(rows) -> dict:
    """{(method, source): {metric: {"median", "q25", "q75", "n"}}, plus "ok"/"failed"/"error" counts} over the
    rows whose status is ok."""
    out: dict = {}
    for (method, source), group in rows.groupby(["method", "source"], sort=True):
        ok = group[group["status"] == "ok"]
        entry = {"counts": {s: int((group["status"] == s).sum()) for s in ("ok", "failed", "error")},
                 "metrics": {}, "seconds": {}}
        for metric in metric_columns(rows):
            values = ok[metric].to_numpy(dtype=float) if metric in ok else np.zeros(0)
            values = values[np.isfinite(values)]
            if values.size:
                median, q25, q75 = _quartiles(values)
                entry["metrics"][metric] = {"median": median, "q25": q25, "q75": q75, "n": int(values.size)}
        for column in [c for c in rows.columns if c.startswith("seconds_")]:
            values = ok[column].to_numpy(dtype=float)
            values = values[np.isfinite(values)]
            if values.size:
                entry["seconds"][column.removeprefix("seconds_")] = float(np.median(values))
        out[(method, source)] = entry
    return out


def registered_scores(task: str, models: str | None) -> dict[str, float]:
    """What the model `load` gives for `task` scored on its held-out split when it was registered (the shipped
    default: its metrics_report.json; a registry: the champion's, else the latest version's, logged metrics)."""
    from trainers.models import DEFAULT_MODELS

    if models is None:
        path = DEFAULT_MODELS / task / "metrics_report.json"
        test = json.loads(path.read_text()).get("test", {}) if path.exists() else {}
    else:
        registry = open_registry(models, create=False)
        name = get_task(task).model_name
        found = registry.champion(name) or registry.latest(name)
        test = dict(found.metrics) if found is not None else {}
    return {k: float(test[k]) for k in _REGISTERED.get(task, ()) if k in test}


def _versions() -> list[str]:
    from importlib import metadata

    out = []
    for name in _PACKAGES:
        try:
            out.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            continue
    return out


SUMMARY_WIDTH = 100  # summary.md reads in a terminal: no line wider than this (a path longer than it is kept whole)


def _cell(stats: dict | None) -> str:
    if stats is None:
        return "-"
    return f"{stats['median']:.3f} [{stats['q25']:.3f}, {stats['q75']:.3f}]"


def _wrapped(text: str, indent: str = "") -> list[str]:
    """A paragraph or list item as lines of at most SUMMARY_WIDTH (the continuation indented by `indent`)."""
    return textwrap.wrap(text, SUMMARY_WIDTH, subsequent_indent=indent, break_long_words=False,
                         break_on_hyphens=False)


def _source_label(source: str, part: str) -> str:
    """What a row's source means in the summary: under `--part all` a dataset's trees are not held out."""
    if source == "held-out":
        return "all trees" if part == "all" else f"{part} part"
    return "real inputs" if source == "input" else source


def _trees_line(plan, info) -> str:
    picked = plan.picked.get(info.path, {})
    taken = sum(picked.values())
    what = "trees" if plan.record["part"] == "all" else f"held-out trees ({plan.record['part']} part)"
    by_species = ", ".join(f"{name} {count}" for name, count in sorted(picked.items()))
    return (f"- {info.path} ({info.name}): {taken} of {len(info.held_out)} {what}, {len(picked)} species: "
            f"{by_species}")


def _summary_markdown(rows, plan, sources: dict, models: str | None, sweep, table: dict) -> str:
    from reconstruct.scoring import METRICS

    part = plan.record["part"]
    which = "every tree (--part all)" if part == "all" else f"the trainers' {part} part (held out)"
    cap = (f", at most {plan.record['trees']} per dataset, picked across its species" if plan.record.get("trees")
           else "")
    trees = f"; trees: {which}{cap}" if plan.datasets else ""
    evals = plan.record["settings"].get("fit_evals")
    fitting = ("" if evals is None else f" Drawing methods fitted to their drawings within {evals} candidate trees "
               "each (--fit-evals)." if evals else " Drawing methods not fitted (--fit-evals 0): their first guesses.")
    lines = ["# Evaluation", "", *_wrapped(f"Methods: {', '.join(plan.methods)}{trees}.{fitting}"), ""]
    if plan.datasets:
        lines += ["Datasets:", ""]
        for info in plan.datasets:
            lines += _wrapped(_trees_line(plan, info), "  ")
        lines.append("")
    if plan.record.get("inputs"):
        lines += [*_wrapped(f"Real inputs: {plan.record['inputs']}."), ""]
    for line in plan.skipped:
        lines += _wrapped(f"- {line}", "  ")
    if plan.skipped:
        lines.append("")
    keys = list(table)
    lines += [*_wrapped("Trees per method: " + "; ".join(
        f"{m} ({_source_label(s, part)}) {table[(m, s)]['counts']['ok']} ok" for m, s in keys) + "."), ""]
    # One row per (metric, method), not a column per method: the table stays narrow however many methods ran.
    body, papers = [], []
    for metric in metric_columns(rows):
        found = [(key, table[key]["metrics"][metric]) for key in keys if metric in table[key]["metrics"]]
        if not found:
            continue
        info = METRICS.get(metric)
        label = info.label if info else metric
        better = "" if info is None else ("higher" if info.higher_is_better else "lower")
        for position, ((method, source), stats) in enumerate(found):
            body.append([label if position == 0 else "", better if position == 0 else "",
                         method if source == "held-out" else f"{method} ({_source_label(source, part)})",
                         _cell(stats), stats["n"]])
        methods_with = {m for (m, _), _ in found}
        if info and info.paper and (not info.paper_method or info.paper_method in methods_with):
            papers.append(f"- {label}{f' ({info.paper_method})' if info.paper_method else ''}: {info.paper}")
    values = np.zeros(0) if sweep is None else sweep["unit_cube_hausdorff"].to_numpy(dtype=float)
    if np.isfinite(values).any():
        median, q25, q75 = _quartiles(values[np.isfinite(values)])
        sweep_info = METRICS["rotation_sweep_unit_cube_hausdorff"]
        body.append([sweep_info.label, "lower", "params", f"{median:.3f} [{q25:.3f}, {q75:.3f}]", len(values)])
        papers.append(f"- {sweep_info.label} (params, n = views): {sweep_info.paper}")
    lines += ["## Metrics (median [q25, q75] over the trees that finished)", "", "```",
              format_table(["metric", "better", "method", "median [q25, q75]", "n"], body), "```", ""]
    if papers:
        lines += ["The papers' figures:", "", *papers, ""]
    stage_rows = []
    for method, source in keys:
        for stage, seconds in table[(method, source)]["seconds"].items():
            stage_rows.append([f"{method} ({_source_label(source, part)})", stage, f"{seconds:.2f}"])
    lines += ["## Stage seconds (median per tree)", "", "```", format_table(["method", "stage", "s"], stage_rows),
              "```", ""]
    failures = rows[rows["status"] != "ok"]
    if len(failures):
        lines += ["## Failures", ""]
        for _, row in failures.iterrows():
            first = str(row["error"]).strip().splitlines()
            lines += _wrapped(f"- {row['method']} {row['tree_id']} ({row['status']}): {first[-1] if first else ''}",
                              "  ")
        lines.append("")
    lines += ["## Models", ""]
    for task, source in sources.items():
        scores = registered_scores(task, models)
        figures = ", ".join(f"{k} {v:.3f}" for k, v in scores.items()) or "no held-out figures recorded"
        lines += _wrapped(f"- {task}: {source}; when registered, on its own test split: {figures}", "  ")
    if not sources:
        lines.append("- none (no method of this evaluation uses a trained network)")
    lines += ["", "## Made with", ""]
    for item in (f"- machine: {platform.node()}, {platform.machine()}, {platform.processor() or 'cpu'}, "
                 f"Python {platform.python_version()}, {platform.platform()}",
                 f"- treefarm {code_version()}; {', '.join(_versions())}",
                 f"- settings: {json.dumps(plan.record['settings'], sort_keys=True)}"):
        lines += _wrapped(item, "  ")
    lines.append("")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ plots
def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> Path:
    import io

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=80, metadata={"Software": None})
    _pyplot().close(fig)
    write_atomically(path, buffer.getvalue())
    return path


def _distribution_plot(rows, by: str, path: Path) -> Path | None:
    """One panel per metric: the metric's values per `by` group (method, or method/species: the HEADLINE metrics
    only) as box plots. Fixed margins, not tight_layout: that alone took seconds a plot."""
    from reconstruct.scoring import METRICS

    plt = _pyplot()
    ok = rows[rows["status"] == "ok"]
    metrics = [m for m in metric_columns(rows) if m in ok and np.isfinite(ok[m].to_numpy(dtype=float)).any()
               and (by == "method" or m in HEADLINE)]
    if not metrics:
        return None
    groups = (ok["method"] if by == "method" else ok["method"] + " / " + ok["species"].fillna("?")).astype(str)
    names = sorted(groups.unique())
    columns = 3 if by == "method" else 2
    n_rows = int(np.ceil(len(metrics) / columns))
    height = max(2.4, 0.22 * len(names) + 1.0)
    fig, axes = plt.subplots(n_rows, columns, figsize=(5.2 * columns, height * n_rows), squeeze=False)
    fig.subplots_adjust(left=0.1 if by == "method" else 0.2, right=0.98, top=1 - 0.35 / (height * n_rows),
                        bottom=0.3 / (height * n_rows), wspace=0.45 if by == "method" else 0.75, hspace=0.55)
    for ax, metric in zip(axes.flat, metrics):
        data, labels = [], []
        for name in names:
            values = ok.loc[groups == name, metric].to_numpy(dtype=float)
            values = values[np.isfinite(values)]
            if values.size:
                data.append(values)
                labels.append(name)
        ax.boxplot(data, orientation="horizontal", tick_labels=labels, widths=0.6)
        info = METRICS.get(metric)
        ax.set_title((info.label if info else metric) + ("" if info is None else
                                                          " (higher better)" if info.higher_is_better
                                                          else " (lower better)"), fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(metrics):]:
        ax.axis("off")
    return _save(fig, path)


def _gallery(rows, report: Path, method: str, path: Path) -> Path | None:
    """The method's best, median and worst trees by its gallery metric: their panels stacked, labelled."""
    import cv2

    ok = rows[(rows["method"] == method) & (rows["status"] == "ok") & rows["panel"].notna()] \
        if "panel" in rows else rows.iloc[0:0]
    metric = next((m for m in GALLERY_METRIC if m in ok and np.isfinite(ok[m].to_numpy(dtype=float)).any()), None)
    if metric is None or not len(ok):
        return None
    from reconstruct.scoring import METRICS

    ranked = ok[np.isfinite(ok[metric].to_numpy(dtype=float))].sort_values(
        metric, ascending=not METRICS[metric].higher_is_better, kind="stable")
    picks = {"best": 0, "median": len(ranked) // 2, "worst": len(ranked) - 1}
    images = []
    for label, position in picks.items():
        row = ranked.iloc[position]
        panel = read_image(report / row["panel"])
        band = np.full((26, panel.shape[1], 3), 255, np.uint8)
        cv2.putText(band, f"{label}: {METRICS[metric].label} = {row[metric]:.3f}  ({row['tree_id']})", (6, 18),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
        images.append(np.concatenate([band, panel]))
    width = max(image.shape[1] for image in images)
    images = [np.pad(image, ((0, 0), (0, width - image.shape[1]), (0, 0)), constant_values=255) for image in images]
    write_atomically(path, png_bytes(np.concatenate(images), 6))
    return path


def _sweep_plot(sweep, path: Path) -> Path:
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 3))
    ax.plot(sweep["azimuth_deg"], sweep["unit_cube_hausdorff"], marker=".")
    ax.axhline(0.03, color="grey", linestyle="--", label="TreeSketchNet ~0.03")
    ax.set_xlabel("camera azimuth, degrees")
    ax.set_ylabel("unit-cube Hausdorff")
    ax.set_title(f"rotation sweep: {sweep['species'].iloc[0]} {sweep['tree_id'].iloc[0]} (params)", fontsize=9)
    ax.legend(fontsize=8)
    fig.subplots_adjust(left=0.12, right=0.98, top=0.88, bottom=0.18)
    return _save(fig, path)


def write_report(report: Path, rows, plan, sources: dict, models: str | None, sweep) -> dict[str, Path]:
    """summary.md and the plots; returns what was written, by name."""
    table = summary_table(rows)
    paths = {}
    write_atomically(report / SUMMARY_FILE, _summary_markdown(rows, plan, sources, models, sweep, table).encode())
    paths["summary"] = report / SUMMARY_FILE
    for by, name in (("method", "metrics_by_method.png"), ("species", "metrics_by_species.png")):
        written = _distribution_plot(rows, by, report / name)
        if written:
            paths[name] = written
    for method in sorted(rows["method"].unique()):
        written = _gallery(rows, report, method, report / f"gallery_{method}.png")
        if written:
            paths[f"gallery_{method}"] = written
    if sweep is not None and len(sweep):
        paths["sweep"] = _sweep_plot(sweep, report / "sweep.png")
    return paths
