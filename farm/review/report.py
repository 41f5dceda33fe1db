"""An evaluation report as the review server reads it: `farm evaluate`'s metrics.parquet rows, worst first.

`EvaluationReport(path)` reads REPORT_DIR/evaluation.json and metrics.parquet once; `rows()` gives JSON-safe dicts
sorted worst first (failed and errored rows, then by each method's rank metric), `panel_png(i)` one row's panel.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from farm.dataset import Location, read_format_json
from farm.evaluate.job import FORMAT, ID_COLUMNS, JOB_FILE, METRICS_FILE
from farm.evaluate.report import GALLERY_METRIC, metric_columns

from .index import NotFound
from .store import ReviewError

# reconstruct.scoring's METRICS is imported where used: the reconstruct package imports torch, which the review
# server does not otherwise need.

__all__ = ["EvaluationReport", "is_report", "ROW_FILTERS"]

# Query fields of a rows request (besides the token).
ROW_FILTERS = ("method",)


def is_report(path: str | Path) -> bool:
    """Whether `path` is an evaluation report folder (it holds evaluation.json)."""
    return (Path(path) / JOB_FILE).is_file()


def _finite(value) -> float | None:
    """A metric value as a Python float, or None where it is missing (None, NaN, inf)."""
    if value is None:
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def _text(value) -> str | None:
    """An id or message cell as a string, or None where it is missing (None or pandas' NaN)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return None
    return str(value)


class EvaluationReport:
    """One finished evaluation report folder, read once; read-only afterwards (safe to share between threads).

    path : the folder `farm evaluate --out` wrote (evaluation.json, metrics.parquet, panels/METHOD/KEY.png).
    """

    def __init__(self, path: str | Path):
        import pandas as pd

        self.path = Path(path)
        metrics_file = self.path / METRICS_FILE
        self.job = read_format_json(Location.resolve(str(self.path)), JOB_FILE, FORMAT, error=ReviewError,
                                    hint="not an evaluation report (allowed a folder `farm evaluate --out` wrote)")
        if not metrics_file.is_file():
            raise ReviewError(f"{self.path} holds no {METRICS_FILE}: the evaluation has not finished "
                              f"(rerun `farm evaluate ... --out {self.path}` to complete it)")
        frame = pd.read_parquet(metrics_file)
        missing = [c for c in ID_COLUMNS if c not in frame.columns]
        if missing:
            raise ReviewError(f"{metrics_file} lacks column(s) {', '.join(missing)}: allowed a `farm evaluate` table")
        self.metrics = [m for m in metric_columns(frame)
                        if np.isfinite(frame[m].to_numpy(dtype=float)).any()]
        self.seconds = [c for c in frame.columns if c.startswith("seconds_")]
        self.rank_metrics = self._rank_metrics(frame)
        self._rows = self._sorted_rows(frame)

    # ------------------------------------------------------------------ ranking
    def _rank_metrics(self, frame) -> dict[tuple[str, str], str | None]:
        """(method, source) -> the first GALLERY_METRIC its ok rows have a finite value for (None: no such metric).
        Held-out trees and real inputs rank apart: an input has no ground truth, so no unseen-view metric."""
        out = {}
        for (method, source), group in frame.groupby(["method", "source"], sort=True):
            ok = group[group["status"] == "ok"]
            out[(str(method), str(source))] = next(
                (m for m in GALLERY_METRIC if m in ok and np.isfinite(ok[m].to_numpy(dtype=float)).any()), None)
        return out

    def _sorted_rows(self, frame) -> list[dict]:
        """Every row as a dict, worst first: not-ok rows; then ok rows by their worst-first position among the rows
        ranked by the same metric (so one metric's values compare across methods, different metrics interleave
        by share); then ok rows without a rank value. Ties keep method, source, dataset and tree order."""
        from reconstruct.scoring import METRICS

        rows = [self._row(record) for record in frame.to_dict("records")]
        by_metric: dict[str, list[dict]] = {}
        for row in rows:
            row["rank_metric"] = self.rank_metrics.get((row["method"], row["source"]))
            row["rank_value"] = row["metrics"].get(row["rank_metric"]) if row["rank_metric"] else None
            row["rank"] = row["rank_of"] = None
            if row["status"] == "ok" and row["rank_value"] is not None:
                by_metric.setdefault(row["rank_metric"], []).append(row)
        for metric, pool in by_metric.items():
            worse_first = -1.0 if METRICS[metric].higher_is_better else 1.0
            pool.sort(key=lambda r: (-worse_first * r["rank_value"], r["method"], r["source"], r["dataset"],
                                     r["tree_id"]))
            for position, row in enumerate(pool):
                row["rank"], row["rank_of"] = position + 1, len(pool)

        def key(row: dict):
            tie = (row["method"], row["source"], row["dataset"], row["tree_id"])
            if row["status"] != "ok":
                return (0, 0.0, *tie)  # no reconstruction at all: the worst rows
            if row["rank"] is None:
                return (2, 0.0, *tie)
            return (1, (row["rank"] - 1) / row["rank_of"], *tie)

        rows.sort(key=key)
        for index, row in enumerate(rows):
            row["index"] = index
        return rows

    def _row(self, record: dict) -> dict:
        models = record.get("models")
        try:
            models = json.loads(models) if isinstance(models, str) and models else {}
        except ValueError:
            models = {"unreadable": models}
        panel = record.get("panel")
        return {
            **{c: _text(record.get(c)) for c in ID_COLUMNS},
            "metrics": {m: v for m in self.metrics if (v := _finite(record.get(m))) is not None},
            "seconds": {c.removeprefix("seconds_"): v for c in self.seconds
                        if (v := _finite(record.get(c))) is not None},
            "models": models,
            "panel": panel if isinstance(panel, str) and panel else None,
        }

    # ------------------------------------------------------------------ reads
    @property
    def name(self) -> str:
        return self.path.resolve().name

    def summary(self) -> dict:
        """The job record, row counts, methods, and the metric columns with their labels and directions."""
        from reconstruct.scoring import METRICS

        counts = {s: sum(r["status"] == s for r in self._rows) for s in ("ok", "failed", "error")}
        columns = []
        for name in self.metrics:
            info = METRICS.get(name)
            columns.append({"name": name, "label": info.label if info else name,
                            "higher_is_better": info.higher_is_better if info else None,
                            "paper": info.paper if info else ""})
        return {"report": self.name, "path": str(self.path), "job": self.job, "rows": len(self._rows),
                "counts": counts, "methods": sorted({r["method"] for r in self._rows}),
                "sources": sorted({r["source"] for r in self._rows}), "columns": columns,
                "rank_metrics": [{"method": m, "source": s, "metric": metric}
                                 for (m, s), metric in self.rank_metrics.items()]}

    def rows(self, method: str | None = None) -> list[dict]:
        """The rows worst first (each with `index`, its place in the unfiltered list), of one method when given."""
        if method is None:
            return list(self._rows)
        methods = sorted({r["method"] for r in self._rows})
        if method not in methods:
            raise ReviewError(f"method filter {method!r} is not in this report: allowed {', '.join(methods)}")
        return [r for r in self._rows if r["method"] == method]

    def rows_query(self, params: dict[str, str]) -> list[dict]:
        """`rows` for a query string's fields (every value a string); an unknown field is refused."""
        unknown = set(params) - set(ROW_FILTERS) - {"token"}
        if unknown:
            raise ReviewError(f"unknown row filter(s) {', '.join(sorted(unknown))}; allowed {', '.join(ROW_FILTERS)}")
        return self.rows(params.get("method") or None)

    def row(self, index: int) -> dict:
        if not 0 <= index < len(self._rows):
            raise NotFound(f"no row {index} in report {self.path}: allowed 0 to {len(self._rows) - 1}")
        return self._rows[index]

    def panel_png(self, index: int) -> bytes:
        """Row `index`'s panel (input | reconstruction | ground truth) as PNG bytes."""
        row = self.row(index)
        if row["panel"] is None:
            raise NotFound(f"row {index} ({row['method']} {row['tree_id']}, {row['status']}) has no panel")
        # The path comes from the table, not the request; still refuse one that leads out of the report.
        target = (self.path / row["panel"]).resolve()
        if Path(row["panel"]).is_absolute() or not target.is_relative_to(self.path.resolve()):
            raise PermissionError(f"row {index}'s panel {row['panel']!r} leads outside the report folder")
        if not target.is_file():
            raise NotFound(f"row {index}'s panel {self.path / row['panel']} is missing")
        return target.read_bytes()
