"""What every part of the evaluation job shares: the report folder's names, a unit of work (one method on one
tree), the error, the true tree of a unit and its views, each worker's kept context, and atomic writes."""
from __future__ import annotations

import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import species
from farm.dataset import output_columns, read_columns, read_manifest, stored_float_outputs
from farm.dataset.image_codec import decode_map
from renderers import Camera
from species.errors import TreefarmError

from .methods import METHODS, EvalSettings, HeldOutTree, MethodContext

__all__ = ["JOB_FILE", "ROWS", "PANELS", "METRICS_FILE", "FORMAT", "PARTS", "ID_COLUMNS", "EvaluationError", "Unit",
           "load_tree", "worker_context", "write_atomically"]

JOB_FILE = "evaluation.json"
ROWS, PANELS = "rows", "panels"
METRICS_FILE = "metrics.parquet"
FORMAT = "treefarm-evaluation/1"
PARTS = ("test", "val", "all")
ID_COLUMNS = ["method", "source", "dataset", "spec_digest", "tree_id", "species", "status", "error"]


class EvaluationError(TreefarmError):
    """An evaluation that cannot run as asked: an unknown method, an empty dataset, a missing model, a report
    folder of another job."""


@dataclass(frozen=True)
class Unit:
    """One (method, tree) to evaluate: a dataset's tree, or a real input file (source "input")."""

    method: str
    source: str
    dataset: str
    spec_digest: str
    tree_id: str
    views: tuple[tuple[str, str], ...] = ()  # (method's view name, the dataset's view_name)

    @property
    def key(self) -> str:
        stem = Path(self.tree_id).name if self.source == "input" else self.tree_id
        return f"{self.spec_digest[:12]}-{stem}"


def load_tree(unit: Unit) -> HeldOutTree:
    """The unit's true tree (`species.rebuild` of the stored dictionary) and the views its method reads."""
    import pyarrow.compute as pc

    this_tree = pc.field("tree_id") == unit.tree_id
    found = read_columns(unit.dataset, "trees", ["tree_id", "species", "params_json"], filters=this_tree).to_pylist()
    if not found:
        raise EvaluationError(f"tree {unit.tree_id} is not in {unit.dataset}")
    params, name = json.loads(found[0]["params_json"]), found[0]["species"]
    skeleton, mesh = species.rebuild(params)
    tree = HeldOutTree(unit.dataset, unit.spec_digest, unit.tree_id, name, params, skeleton, mesh)
    if not unit.views:
        return tree
    needs = METHODS[unit.method].needs
    stored = read_manifest(unit.dataset)["job"]["render"]["outputs"]
    outputs = [o for o in (*needs.outputs, *needs.optional) if o in stored]
    columns = ["tree_id", "view_name", "camera_json", *output_columns(outputs, stored_float_outputs(unit.dataset))]
    wanted = {dataset_view: view for view, dataset_view in unit.views}
    for row in read_columns(unit.dataset, "views", columns, filters=this_tree).to_pylist():
        if row["view_name"] in wanted:
            images = {o: decode_map(row[o], row.get(f"{o}_scale"), row.get(f"{o}_offset")) for o in outputs}
            tree.views[wanted[row["view_name"]]] = (Camera.from_dict(json.loads(row["camera_json"])), images)
    missing = sorted(set(wanted.values()) - set(tree.views))
    if missing:
        raise EvaluationError(f"tree {unit.tree_id} of {unit.dataset} has no {', '.join(missing)} view")
    return tree


_CONTEXTS: dict[str, MethodContext] = {}  # per worker process: the renderer and networks, kept between units


def worker_context(models: str | None, settings: EvalSettings) -> MethodContext:
    key = json.dumps([models, asdict(settings)])
    if key not in _CONTEXTS:
        _CONTEXTS[key] = MethodContext(models, settings)
    return _CONTEXTS[key]


def write_atomically(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.{os.getpid()}.partial")
    partial.write_bytes(data)
    os.replace(partial, path)


