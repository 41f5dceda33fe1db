"""The dataset format's tables: their schemas, part file names and bytes, and a Skeleton from a trees row.

Layout: manifest.json, trees/part-NNNNN.parquet, views/part-NNNNN.parquet (docs/dataset.md). Part files are
serialized with fixed writer options, so the same rows give the same bytes on every worker.
"""
from __future__ import annotations

import json
from contextlib import contextmanager
from typing import Collection, Iterable, Sequence

import numpy as np

from species.errors import TreefarmError
from species.skeleton import Skeleton, SkeletonError

__all__ = ["DATASET_FORMAT", "SCHEMA_VERSION", "TABLES", "SKELETON_COLUMNS", "DatasetError", "reading_part",
           "trees_schema", "views_schema", "float_outputs_of", "output_columns", "skeleton_from_row", "part_name",
           "serialize_table"]

# manifest.json's "format" (docs/dataset.md).
DATASET_FORMAT = "treefarm-dataset"
SCHEMA_VERSION = 1
TABLES = ("trees", "views")
# The trees-table columns a Skeleton is stored in, flattened row-major: (N, 3) positions, (M, 4, 4) leaves.
SKELETON_COLUMNS = ("positions", "parent", "radius", "order", "leaves", "leaf_node")
# Fixed writer options: part files are compared byte for byte across runs.
_PARQUET_OPTIONS = dict(compression="zstd", compression_level=3, row_group_size=4096, use_dictionary=True,
                        write_statistics=True, data_page_version="2.0", version="2.6")


class DatasetError(TreefarmError):
    """A dataset folder is missing, incomplete or damaged; the message names the file."""


@contextmanager
def reading_part(file: str):
    """Raise Parquet's refusal of a part file read inside the block (truncated, corrupted) as a DatasetError
    naming the file; Arrow's own message does not name it."""
    import pyarrow

    try:
        yield
    except (pyarrow.ArrowInvalid, OSError) as exc:
        reason = " ".join(str(exc).split())
        raise DatasetError(f"part file {file} cannot be read ({reason}): `farm validate` names the damaged "
                           f"files, `farm generate` with the same spec regenerates them") from None


def _pa():
    import pyarrow

    return pyarrow


def trees_schema():
    """One row per tree. Skeleton arrays are flattened lists (positions: n_nodes * 3, leaves: n_leaves * 16)."""
    pa = _pa()
    f32, i32 = pa.float32(), pa.int32()
    return pa.schema([
        ("tree_id", pa.string()), ("index", pa.int64()), ("shard", i32), ("species", pa.string()),
        ("generator", pa.string()), ("seed", pa.int64()), ("params_json", pa.string()),
        ("n_nodes", i32), ("positions", pa.list_(f32)), ("parent", pa.list_(i32)), ("radius", pa.list_(f32)),
        ("order", pa.list_(pa.uint8())), ("leaves", pa.list_(f32)), ("leaf_node", pa.list_(i32)),
        ("glb", pa.binary()),
        ("height", f32), ("crown_radius", f32), ("n_branches", i32), ("n_leaves", i32),
        ("bark_triangles", i32), ("leaf_triangles", i32), ("n_vertices", i32), ("n_views", i32),
        ("error", pa.string()),
    ], metadata={"treefarm.table": "trees", "treefarm.schema_version": str(SCHEMA_VERSION)})


def views_schema(outputs: Sequence[str], float_outputs: Collection[str]):
    """One row per (tree, view): camera JSON and one PNG column per output, plus `<name>_scale` and
    `<name>_offset` for the float maps among them (`float_outputs`: the writer learns them from
    `renderers.FLOAT_OUTPUTS`, a reader from the stored part files, `float_outputs_of`)."""
    pa = _pa()
    fields = [("tree_id", pa.string()), ("index", pa.int64()), ("shard", pa.int32()), ("view", pa.int32()),
              ("view_name", pa.string()), ("camera_json", pa.string())]
    for name in outputs:
        fields.append((name, pa.binary()))
        if name in float_outputs:
            fields += [(f"{name}_scale", pa.float64()), (f"{name}_offset", pa.float64())]
    return pa.schema(fields, metadata={"treefarm.table": "views", "treefarm.schema_version": str(SCHEMA_VERSION),
                                       "treefarm.outputs": json.dumps(list(outputs))})


def float_outputs_of(columns: Iterable[str]) -> frozenset[str]:
    """The float maps among a views table's columns (a schema's `names`, a table's `column_names`): the outputs
    stored with `<name>_scale` and `<name>_offset` columns."""
    names = set(columns)
    return frozenset(name for name in names if f"{name}_scale" in names and f"{name}_offset" in names)


def output_columns(outputs: Iterable[str], float_outputs: Collection[str]) -> list[str]:
    """The views-table columns of some outputs: each output's PNG column, then its scale and offset if a float map."""
    return [column for name in outputs
            for column in ((name, f"{name}_scale", f"{name}_offset") if name in float_outputs else (name,))]


def skeleton_from_row(row: dict) -> Skeleton:
    """The Skeleton of one trees-table row: a dict with the SKELETON_COLUMNS as flat lists or numpy arrays
    (`pyarrow.Table.to_pylist()`, a pandas row's `to_dict()`). The inverse of the pipeline's tree row
    (`farm.tree_chain.tree_row`); a failed tree's row (no skeleton, `error` set) raises DatasetError."""
    if not isinstance(row, dict):
        raise DatasetError(f"a trees row must be a dict of columns; got {type(row).__name__}")
    name = row.get("tree_id", "?")
    missing = [column for column in SKELETON_COLUMNS if column not in row]
    if missing:
        raise DatasetError(f"trees row {name} lacks the skeleton columns {', '.join(missing)}: read them with the "
                           f"row (allowed: a row holding {', '.join(SKELETON_COLUMNS)})")
    if any(row[column] is None for column in SKELETON_COLUMNS):
        reason = row.get("error") or "its skeleton columns are empty"
        raise DatasetError(f"trees row {name} has no skeleton: the tree failed ({reason})")
    arrays = {column: np.asarray(row[column]).ravel() for column in SKELETON_COLUMNS}
    if arrays["positions"].size % 3 or arrays["leaves"].size % 16:
        raise DatasetError(f"trees row {name}: positions ({arrays['positions'].size} values) must hold 3 per node "
                           f"and leaves ({arrays['leaves'].size} values) 16 per leaf")
    n_nodes = row.get("n_nodes")
    if n_nodes is not None and arrays["positions"].size != 3 * int(n_nodes):
        raise DatasetError(f"trees row {name}: positions hold {arrays['positions'].size // 3} nodes but n_nodes is "
                           f"{n_nodes}")
    try:
        return Skeleton(arrays["positions"].reshape(-1, 3), arrays["parent"], arrays["radius"], arrays["order"],
                        arrays["leaves"].reshape(-1, 4, 4), arrays["leaf_node"])
    except SkeletonError as exc:
        raise DatasetError(f"trees row {name} holds an invalid skeleton: {exc}") from None


def part_name(table: str, shard: int) -> str:
    return f"{table}/part-{shard:05d}.parquet"


def serialize_table(rows: list[dict], schema) -> bytes:
    """Rows as the bytes of one Parquet file (fixed options, no pandas metadata, no timestamps)."""
    import pyarrow.parquet as pq

    table = _pa().Table.from_pylist(rows, schema=schema)
    sink = _pa().BufferOutputStream()
    pq.write_table(table, sink, **_PARQUET_OPTIONS)
    return sink.getvalue().to_pybytes()
