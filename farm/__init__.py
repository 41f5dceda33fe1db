"""treefarm's top floor: the farm that makes datasets and asset libraries of trees on Ray, evaluates the
reconstruction methods, serves the review client, and the `farm` command line over all of it.

Entry points (each imported on first use, see below):
- generation jobs: `load_spec(path)`, `default_spec()`, `JobSpec` (`farm.jobs`) and `run_job(spec, out, workers,
  address)`, `ray_connection(address, workers)` (`farm.pipeline`);
- asset libraries: `load_library_spec(path)`, `LibrarySpec`, `run_library(spec, out)`, `validate_library(folder)`,
  `add_asset(folder, species, seed)` (`farm.library`);
- evaluation: `plan_evaluation(...)`, `run_evaluation(plan, out)`, `compare_reports(a, b)` (`farm.evaluate`);
- review: `ReviewServer`, `export_reviews(dataset, store)` (`farm.review`);
- a dataset's table as Ray Data: `to_ray(path, table)` (`farm.ray_data`).
Subpackages: `farm.dataset` (the dataset format, a floor of its own that `trainers` and `reconstruct` read),
`farm.commands` and `farm.cli` (the command line: `farm.cli.main`).
"""
from __future__ import annotations

import importlib

# Public name -> the module defining it, imported when the name is first read (PEP 562): `farm --help` starts
# from this package, and the lower floors import `farm.dataset` through it, so it imports nothing itself.
_HOMES = {
    "JobSpec": "farm.jobs", "JobSpecError": "farm.jobs", "default_spec": "farm.jobs", "load_spec": "farm.jobs",
    "spec_to_yaml": "farm.jobs",
    "JobError": "farm.pipeline", "run_job": "farm.pipeline", "ray_connection": "farm.pipeline",
    "LibrarySpec": "farm.library", "LibrarySpecError": "farm.library", "LibraryError": "farm.library",
    "load_library_spec": "farm.library", "default_library_spec": "farm.library", "run_library": "farm.library",
    "validate_library": "farm.library", "add_asset": "farm.library",
    "EvaluationError": "farm.evaluate", "plan_evaluation": "farm.evaluate", "run_evaluation": "farm.evaluate",
    "compare_reports": "farm.evaluate",
    "ReviewServer": "farm.review", "ReviewError": "farm.review", "export_reviews": "farm.review",
    "to_ray": "farm.ray_data",
}

__all__ = list(_HOMES)


def __getattr__(name: str):
    if name not in _HOMES:
        raise AttributeError(f"module 'farm' has no attribute {name!r}")
    value = getattr(importlib.import_module(_HOMES[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
