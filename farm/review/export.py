"""`farm review export`: the reviewers' verdicts as a Parquet table beside the dataset, joinable by tree_id.

Output: DIR/reviews/part-00000.parquet with one row per (tree_id, reviewer): verdict, note and time (UTC),
written whole under a temporary name and renamed, sorted by tree id then reviewer.
"""
from __future__ import annotations

from farm.dataset import read_manifest
from farm.dataset.storage import Location

from .store import ReviewStore

__all__ = ["REVIEWS_PART", "reviews_schema", "export_reviews"]

REVIEWS_PART = "reviews/part-00000.parquet"


def reviews_schema():
    import pyarrow as pa

    return pa.schema([("tree_id", pa.string()), ("reviewer", pa.string()), ("verdict", pa.string()),
                      ("note", pa.string()), ("time", pa.timestamp("ms", tz="UTC"))],
                     metadata={"treefarm.table": "reviews"})


def export_reviews(dataset: str, store: ReviewStore) -> tuple[str, int]:
    """Write every stored verdict to DATASET/reviews/part-00000.parquet; returns (path, rows)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    location = Location.resolve(dataset)
    read_manifest(location)  # a dataset, not any folder
    verdicts = store.verdicts()
    columns = {name: [v[name] for v in verdicts] for name in ("tree_id", "reviewer", "verdict", "note")}
    columns["time"] = [v["time_ms"] for v in verdicts]
    table = pa.Table.from_pydict(columns, schema=reviews_schema())
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    location.write_atomic(REVIEWS_PART, sink.getvalue().to_pybytes())
    return location.path(REVIEWS_PART), table.num_rows
