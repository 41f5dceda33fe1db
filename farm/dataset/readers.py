"""Readers of a finished dataset: its manifest, its part files, some columns of a table across them, and each
table through pyarrow, pandas, DuckDB, Ray Data and Hugging Face (torch: `torch_dataset`)."""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterable, Sequence

from .format_json import read_format_json
from .schema import (DATASET_FORMAT, TABLES, DatasetError, float_outputs_of, reading_part, trees_schema,
                     views_schema)
from .storage import Location

__all__ = ["read_manifest", "part_files", "read_columns", "read_part", "open_part", "stored_float_outputs", "open",
           "to_pandas", "duckdb_connect", "to_huggingface"]


def read_manifest(path: str | Location) -> dict:
    """The dataset's manifest.json as a dict; DatasetError if the folder has none (job unfinished?) or it is not
    a treefarm dataset's manifest."""
    location = path if isinstance(path, Location) else Location.resolve(path)
    return read_format_json(location, "manifest.json", DATASET_FORMAT,
                            hint=f"not a finished treefarm dataset (run `farm status {location.uri}` to see an "
                                 f"unfinished job)")


def part_files(path: str | Location, table: str = "trees") -> tuple[Location, list[str]]:
    """The manifest's part files of one table, as paths on the location's filesystem."""
    if table not in TABLES:
        raise DatasetError(f"unknown table {table!r}; known: {', '.join(TABLES)}")
    location = path if isinstance(path, Location) else Location.resolve(path)
    manifest = read_manifest(location)
    return location, [location.path(shard[table]["path"]) for shard in manifest["shards"]]


def read_columns(path: str | Location, table: str, columns: Sequence[str], *, filters=None,
                 memory_map: bool = False):
    """Some columns of one table (`trees` or `views`) across the manifest's part files, as one `pyarrow.Table`
    whose rows keep the part files' order (shard, then row).

    filters    : a `pyarrow.compute` expression a row must match (`pc.field("tree_id") == "t"`), or None.
    memory_map : map local part files rather than read them (the PNG bytes then stay in the page cache until used).
    DatasetError for an unknown table, a dataset without a manifest, and a part file Parquet refuses (named).
    """
    import pyarrow as pa

    location, files = part_files(path, table)
    if not files:
        # A manifest without shards: the asked columns, no rows. A views schema with every output's scale and
        # offset holds any column a views part can have.
        outputs = read_manifest(location)["job"]["render"]["outputs"]
        schema = trees_schema() if table == "trees" else views_schema(outputs, float_outputs=outputs)
        return pa.schema([schema.field(name) for name in columns]).empty_table()
    return pa.concat_tables([read_part(location, file, columns, filters=filters, memory_map=memory_map)
                             for file in files])


def read_part(location: Location, file: str, columns: Sequence[str], *, filters=None, memory_map: bool = False):
    """Some columns of one Parquet file on the location (`file` as `part_files` gives it), as a `pyarrow.Table`;
    DatasetError naming the file when Parquet refuses it. `filters` and `memory_map` as in `read_columns`."""
    import pyarrow.parquet as pq

    with reading_part(file):
        return pq.read_table(file, columns=list(columns), filters=filters, filesystem=location.filesystem,
                             memory_map=memory_map and location.is_local)


@contextmanager
def open_part(location: Location, file: str):
    """A `pyarrow.parquet.ParquetFile` of one file on the location, for reads by row group inside the block; a
    read Parquet refuses there raises DatasetError naming the file."""
    import pyarrow.parquet as pq

    with reading_part(file), location.filesystem.open_input_file(file) as handle:
        yield pq.ParquetFile(handle)


def stored_float_outputs(path: str | Location) -> frozenset[str]:
    """The outputs a dataset stores as float maps: those its views part files store with `<name>_scale` and
    `<name>_offset` columns (read from the first part's schema; none for a dataset without parts)."""
    return _float_outputs_in(*part_files(path, "views"))


def _float_outputs_in(location: Location, files: Sequence[str]) -> frozenset[str]:
    """`stored_float_outputs` of views part files already listed (the manifest read once)."""
    import pyarrow.parquet as pq

    if not files:
        return frozenset()
    with reading_part(files[0]):
        return float_outputs_of(pq.read_schema(files[0], filesystem=location.filesystem).names)


def open(path: str, table: str = "trees"):  # noqa: A001 - the reader's natural name: farm.dataset.open
    """A `pyarrow.dataset.Dataset` over one table (`trees` or `views`) of a finished dataset."""
    import pyarrow.dataset as ds

    location, files = part_files(path, table)
    if table == "trees":
        schema = trees_schema()
    else:
        schema = views_schema(read_manifest(location)["job"]["render"]["outputs"], _float_outputs_in(location, files))
    return ds.dataset(files, schema=schema, format="parquet", filesystem=location.filesystem)


def to_pandas(path: str, table: str = "trees", columns: Iterable[str] | None = None):
    """One table as a pandas DataFrame (pass `columns` to skip the heavy binary ones)."""
    return open(path, table).to_table(columns=list(columns) if columns is not None else None).to_pandas()


def duckdb_connect(path: str):
    """A DuckDB connection with the dataset's tables registered as `trees` and `views`."""
    import duckdb

    connection = duckdb.connect()
    for table in TABLES:
        connection.register(table, open(path, table))
    return connection


def to_huggingface(path: str, table: str = "views", cache_dir: str | None = None, decode_images: bool = True):
    """One table of a local dataset as a Hugging Face `datasets.Dataset` (`load_dataset("parquet")` on the manifest's
    part files, split "train"). With `decode_images`, the 8-bit PNG columns of the views table (`sketch_*`, `mask`,
    `order`, `normals`, `trunk_strokes`) read as `datasets.Image` (PIL images on access); the 16-bit float maps stay
    PNG bytes, decoded with `farm.dataset.image_codec.decode_map` and their `_scale`/`_offset` columns."""
    try:
        import datasets
    except ImportError:
        raise DatasetError("reading a dataset with Hugging Face needs the `datasets` package: "
                           "pip install datasets") from None
    location, files = part_files(path, table)
    if location.filesystem.type_name != "local":
        raise DatasetError(f"to_huggingface reads local datasets; {path!r} is on {location.filesystem.type_name}")
    loaded = datasets.load_dataset("parquet", data_files=files, split="train", cache_dir=cache_dir)
    if decode_images and table == "views":
        non_image = {"tree_id", "index", "shard", "view", "view_name", "camera_json",
                     *float_outputs_of(loaded.features)}
        for column, feature in loaded.features.items():
            if column not in non_image and getattr(feature, "dtype", "") == "binary":
                loaded = loaded.cast_column(column, datasets.Image())
    return loaded
