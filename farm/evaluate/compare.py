"""`farm evaluate compare A B`: what changed between two evaluation reports, per method and metric.

Each report's metrics.parquet is summarised as its summary.md is (median over the trees that finished); a row per
(method, source, metric) both reports have: A's and B's medians, the change, and "better" / "worse" / "same" by the
metric's direction (`reconstruct.scoring.METRICS`). A gate (`--fail-if-worse METRIC[:TOLERANCE]`, METRIC `all` for
every metric) is broken when B is worse than A by more than TOLERANCE (the metric's own units, default 0).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from farm.table import format_table

from .report import summary_table
from .units import METRICS_FILE, EvaluationError

# reconstruct.scoring's METRICS is imported where used: the reconstruct package imports torch.

__all__ = ["Change", "compare_reports", "parse_gate", "broken_gates", "format_changes"]


@dataclass(frozen=True)
class Change:
    method: str
    source: str
    metric: str
    a: float
    b: float
    higher_is_better: bool

    @property
    def delta(self) -> float:
        return self.b - self.a

    @property
    def worse_by(self) -> float:
        """How much worse B is than A, in the metric's units (negative: better)."""
        return -self.delta if self.higher_is_better else self.delta

    @property
    def verdict(self) -> str:
        return "same" if abs(self.delta) <= 1e-12 else "worse" if self.worse_by > 0 else "better"


def _summary(report: str | Path) -> dict:
    import pandas as pd

    path = Path(report) / METRICS_FILE
    if not path.is_file():
        raise EvaluationError(f"{report} is not an evaluation report (no {METRICS_FILE}): allowed a folder written "
                              "by farm evaluate --out")
    return summary_table(pd.read_parquet(path))


def compare_reports(a: str | Path, b: str | Path) -> list[Change]:
    """The changes from report `a` to report `b` over the (method, source, metric) both hold."""
    from reconstruct.scoring import METRICS

    first, second = _summary(a), _summary(b)
    changes = []
    for key in sorted(set(first) & set(second)):
        for metric, stats in first[key]["metrics"].items():
            other = second[key]["metrics"].get(metric)
            if other is None:
                continue
            higher = METRICS[metric].higher_is_better if metric in METRICS else True
            changes.append(Change(key[0], key[1], metric, stats["median"], other["median"], higher))
    return changes


def parse_gate(text: str) -> tuple[str, float]:
    """METRIC[:TOLERANCE] -> (metric, tolerance); EvaluationError naming the value for anything else."""
    from reconstruct.scoring import METRICS

    metric, _, tolerance = text.partition(":")
    if metric != "all" and metric not in METRICS:
        raise EvaluationError(f"--fail-if-worse {text}: unknown metric {metric!r}; allowed all or one of "
                              f"{', '.join(METRICS)}")
    try:
        value = float(tolerance) if tolerance else 0.0
    except ValueError:
        value = -1.0
    if not value >= 0:
        raise EvaluationError(f"--fail-if-worse {text}: tolerance {tolerance!r} is invalid: allowed a number >= 0")
    return metric, value


def broken_gates(changes: Sequence[Change], gates: Sequence[tuple[str, float]]) -> list[Change]:
    return [c for c in changes for metric, tolerance in gates
            if metric in ("all", c.metric) and c.worse_by > tolerance]


def format_changes(changes: Sequence[Change]) -> str:
    from reconstruct.scoring import METRICS

    rows = [[f"{c.method} ({c.source})", METRICS[c.metric].label if c.metric in METRICS else c.metric,
             f"{c.a:.4f}", f"{c.b:.4f}", f"{c.delta:+.4f}", c.verdict] for c in changes]
    return format_table(["method", "metric (median)", "A", "B", "B - A", "B is"], rows)
