"""The tables of `farm models list|show` over registry versions and shipped default models, and the warning of a
version that scores worse than its baseline. In: `ModelVersion`s; out: text that fits a terminal.
"""
from __future__ import annotations

from typing import Mapping, Sequence

from .registry import BASELINE_SUFFIX, SHIPPED, ModelVersion, Registry
from .tasks import TASKS

__all__ = ["format_models_table", "format_model_versions", "format_shipped_model", "judged_by", "below_baseline"]


def _number(value: float) -> str:
    return f"{value:.4g}"


def _metric_cells(metrics: Mapping[str, float]) -> dict[str, str]:
    """{metric: 'value (baseline b)'}: each `X_baseline` goes in brackets after `X` (alone if `X` is absent)."""
    cells = {}
    for key in sorted(metrics):
        base = metrics.get(f"{key}{BASELINE_SUFFIX}")
        if key.endswith(BASELINE_SUFFIX) and key[:-len(BASELINE_SUFFIX)] in metrics:
            continue
        cells[key] = _number(metrics[key]) + ("" if base is None else f" ({_number(base)})")
    return cells


def _align(headers: list[str], rows: list[list[str]], right: set[int] = frozenset()) -> str:
    """Columns padded to their widest cell, those in `right` right-aligned, with a rule under the headers."""
    table = [headers] + rows
    widths = [max(len(row[i]) for row in table) for i in range(len(headers))]

    def line(row: list[str]) -> str:
        return "  ".join(c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths)))

    return "\n".join(line(row).rstrip() for row in [headers, ["-" * w for w in widths]] + rows)


def judged_by(version: ModelVersion) -> tuple[str, bool] | None:
    """(metric, higher is better) that judges `version`: its task's (the `task` tag, else the model's name when
    that is a task); None for a model of no known task."""
    task = TASKS.get(version.tags.get("task", version.name))
    return None if task is None else (task.primary_metric, task.higher_is_better)


def below_baseline(version: ModelVersion) -> str | None:
    """A one-line warning when `version` scores worse than its trivial baseline on the metric that judges it
    (a model that has learnt less than the mean); None when it does not, or when it logged no baseline."""
    judged = judged_by(version)
    if judged is None:
        return None
    metric, higher = judged
    value, base = version.metrics.get(metric), version.metrics.get(f"{metric}{BASELINE_SUFFIX}")
    if value is None or base is None or (value >= base if higher else value <= base):
        return None
    shown = "shipped" if SHIPPED in version.aliases else f"v{version.version}"
    return (f"{version.name} {shown} is worse than its baseline: {metric} {_number(value)} against the baseline's "
            f"{_number(base)} ({'higher' if higher else 'lower'} is better)")


def _key_metric(version: ModelVersion) -> str:
    """The metric that judges `version` with its baseline in brackets (the first logged one for a model of no
    known task), marked when it is worse than the baseline."""
    cells = _metric_cells(version.metrics)
    judged = judged_by(version)
    key = judged[0] if judged is not None and judged[0] in cells else next(iter(cells), None)
    if key is None:
        return "-"
    return f"{key} {cells[key]}" + ("  worse than baseline" if below_baseline(version) else "")


def format_models_table(registry: Registry | None, shipped: Sequence[ModelVersion] = (),
                        shipped_from: str = "") -> str:
    """`farm models list`: per model of `registry` its number of versions, the latest and champion versions and the
    metric that judges the champion (the latest where there is no champion) with its baseline in brackets; then the
    `shipped` default models (`trainers.models.shipped_models`, from the folder `shipped_from`) with theirs.
    `farm models show` has every metric."""
    rows, heads = [], []
    if registry is not None:
        names = registry.names()
        heads.append(f"model registry {registry.label}" if names else f"no models in the model registry "
                                                                      f"{registry.label}")
        for name in names:
            versions = registry.versions(name)
            latest = versions[-1] if versions else None
            champion = next((v for v in versions if v.is_champion), None)
            shown = champion or latest
            metric = "-" if shown is None else _key_metric(shown)
            rows.append([name, str(len(versions)), f"v{latest.version}" if latest else "-",
                         f"v{champion.version}" if champion else "-",
                         metric if champion or shown is None else f"(latest) {metric}"])
    if shipped:
        heads.append(f"shipped default models in {shipped_from} (what commands use without --models)")
        rows += [[v.name, "-", "-", SHIPPED, _key_metric(v)] for v in shipped]
    if not rows:
        return "\n".join(heads)
    table = _align(["model", "versions", "latest", "champion", "key metric (baseline)"], rows, right={1, 2, 3})
    return "\n".join(heads) + f"\n\n{table}"


def format_model_versions(registry: Registry, name: str) -> str:
    """`farm models show NAME`: its versions newest first with aliases, creation time and run, then each metric
    per version with its baseline in brackets; the champion's column is marked, and a version worse than its
    baseline has a warning line."""
    return _format_versions(name, registry.versions(name)[::-1], f"the model registry {registry.label}")


def format_shipped_model(version: ModelVersion, folder: str) -> str:
    """`farm models show NAME` of a shipped default model (`trainers.models.shipped_models`): its every metric."""
    return _format_versions(version.name, [version], f"the shipped default models {folder}")


def _format_versions(name: str, versions: list[ModelVersion], where: str) -> str:
    if not versions:
        return f"model {name!r} in {where} has no versions"
    champion = next((v.version for v in versions if v.is_champion), None)
    warnings_ = [f"warning: {line}" for line in map(below_baseline, versions) if line]
    if SHIPPED in versions[0].aliases:
        head = f"model {name}: a shipped default model, {versions[0].source}"
        listing = ""
    else:
        head = (f"model {name} in {where}: {len(versions)} version{'' if len(versions) == 1 else 's'}, latest "
                f"v{versions[0].version}, champion {'-' if champion is None else f'v{champion}'}")
        listing = "\n\n" + _align(["version", "aliases", "created (UTC)", "run"],
                                  [[f"v{v.version}", ", ".join(v.aliases) or "-",
                                    v.created.strftime("%Y-%m-%d %H:%M:%S"), v.run_id] for v in versions], right={0})
    head = "\n".join([head] + warnings_)
    cells = [_metric_cells(v.metrics) for v in versions]
    keys = sorted({k for c in cells for k in c})
    if not keys:
        return f"{head}{listing}\n\nno metrics logged"
    columns = [SHIPPED if SHIPPED in v.aliases else f"v{v.version}" + (" champion" if v.is_champion else "")
               for v in versions]
    metrics = _align(["metric (baseline)"] + columns, [[k] + [c.get(k, "-") for c in cells] for k in keys],
                     right=set(range(1, len(columns) + 1)))
    return f"{head}{listing}\n\n{metrics}"
