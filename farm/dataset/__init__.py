"""The treefarm dataset format, a floor of its own: what `farm generate` writes and every reader opens.

Layout: manifest.json, trees/part-NNNNN.parquet, views/part-NNNNN.parquet (docs/dataset.md). Modules: `schema`
(the tables and their part files' bytes), `readers` (the manifest, part files, columns across them, pyarrow,
pandas, DuckDB, Ray Data, Hugging Face), `manifest` (shard records, the manifest, validation), `storage` (a local
folder or object-store prefix), `format_json` (JSON files that name their format, checked), `image_codec` (maps as
PNG), `image_files` (image files a user gives, read as arrays) and `torch_dataset` (a torch `Dataset` over the
views). It imports only `species`, numpy, pyarrow and the image libraries.
"""
from __future__ import annotations

from .format_json import parse_format_json, read_format_json
from .image_files import IMAGE_SUFFIXES, read_image
from .readers import (duckdb_connect, open, open_part, part_files, read_columns, read_manifest, read_part,
                      stored_float_outputs, to_huggingface, to_pandas)
from .schema import (DATASET_FORMAT, SCHEMA_VERSION, SKELETON_COLUMNS, TABLES, DatasetError, float_outputs_of,
                     output_columns, part_name, reading_part, serialize_table, skeleton_from_row, trees_schema,
                     views_schema)
from .storage import Location

__all__ = ["DATASET_FORMAT", "SCHEMA_VERSION", "TABLES", "SKELETON_COLUMNS", "DatasetError", "reading_part",
           "trees_schema", "views_schema", "float_outputs_of", "output_columns", "skeleton_from_row", "part_name",
           "serialize_table", "read_manifest", "part_files", "read_columns", "read_part", "open_part",
           "stored_float_outputs", "open", "to_pandas",
           "duckdb_connect", "to_huggingface", "parse_format_json", "read_format_json", "Location",
           "read_image", "IMAGE_SUFFIXES", "ViewsDataset"]


def __getattr__(name: str):
    # The torch Dataset is named here but imported on first use: torch is heavy and most readers never need it.
    if name == "ViewsDataset":
        from .torch_dataset import ViewsDataset

        return ViewsDataset
    raise AttributeError(f"module 'farm.dataset' has no attribute {name!r}")
