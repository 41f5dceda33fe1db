"""The evaluation job (`farm evaluate`): every reconstruction method scored on the held-out trees of datasets and
on real inputs, as Ray tasks, written as a report folder; and the comparison of two reports.

Entry points: `plan_evaluation(data, methods, ...)` -> `EvaluationPlan`, `run_evaluation(plan, out, ...)`,
`evaluation_data_spec()` (`job`), `EvalSettings` (`methods`), `compare_reports(a, b)`, `parse_gate(text)`,
`broken_gates(changes, gates)`, `format_changes(changes)` (`compare`), `EvaluationError` (`units`).
Modules, from the bottom up: `methods` (what each method needs and how it is scored), `units` (a unit of work and
the report folder's names), `inputs` (real inputs), `sweep`, `report`, `job`, `compare`.
"""
from __future__ import annotations

from .compare import Change, broken_gates, compare_reports, format_changes, parse_gate
from .job import EvaluationPlan, evaluation_data_spec, plan_evaluation, run_evaluation
from .methods import EvalSettings
from .units import EvaluationError

__all__ = ["plan_evaluation", "run_evaluation", "evaluation_data_spec", "EvaluationPlan", "EvalSettings",
           "compare_reports", "parse_gate", "broken_gates", "format_changes", "Change", "EvaluationError"]
