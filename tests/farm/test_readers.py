"""Readers of a finished dataset: pyarrow, pandas, DuckDB, Ray Data and the torch Dataset see the same rows."""
from __future__ import annotations

import json

import numpy as np
import pytest

import farm.dataset as dataset
from farm.pipeline import run_job
from farm.ray_data import to_ray
from farm_standins import SIZE, StandinChain, standin_spec


@pytest.fixture(scope="module")
def standin_dataset(tmp_path_factory, ray_session):
    spec = standin_spec(species={"standin_a": 3, "standin_b": 2, "broken": 1})
    path = str(tmp_path_factory.mktemp("readers"))
    run_job(spec, path, workers=2, builder_factory=StandinChain, progress=False)
    return spec, path


def test_pyarrow_dataset_has_one_row_per_tree_with_the_trees_schema(standin_dataset):
    spec, path = standin_dataset
    table = dataset.open(path).to_table()
    assert table.schema.equals(dataset.trees_schema(), check_metadata=False)
    assert sorted(table["index"].to_pylist()) == list(range(spec.n_trees))


def test_pandas_skeleton_columns_rebuild_the_node_arrays(standin_dataset):
    _, path = standin_dataset
    frame = dataset.to_pandas(path, columns=["n_nodes", "positions", "parent", "error"])
    good = frame[frame["error"].isna()]
    for n_nodes, positions, parent in zip(good["n_nodes"], good["positions"], good["parent"]):
        assert np.reshape(positions, (-1, 3)).shape == (n_nodes, 3)
        assert parent[0] == -1 and np.all(np.asarray(parent[1:]) < np.arange(1, n_nodes))


def test_duckdb_joins_trees_and_views(standin_dataset):
    spec, path = standin_dataset
    rows = dataset.duckdb_connect(path).execute(
        "SELECT t.species, count(*) FROM views v JOIN trees t USING (tree_id) GROUP BY t.species ORDER BY 1"
    ).fetchall()
    assert rows == [("standin_a", 6), ("standin_b", 4)]  # 2 views per good tree; the broken tree has none


def test_ray_data_reads_every_view(standin_dataset, ray_session):
    _, path = standin_dataset
    views = to_ray(path, "views")
    assert views.count() == 10
    assert set(views.take(1)[0]) >= {"tree_id", "camera_json", "depth", "depth_scale"}


def test_torch_dataset_decodes_images_lazily_to_channel_first_tensors(standin_dataset):
    import torch

    from farm.dataset.torch_dataset import ViewsDataset

    _, path = standin_dataset
    views = ViewsDataset(path, with_params=True)
    item = views[3]
    assert len(views) == 10
    assert item["depth"].dtype == torch.float32 and item["depth"].shape == (1, SIZE, SIZE)
    assert item["silhouette"].shape == (3, SIZE, SIZE) and float(item["silhouette"].max()) <= 1.0
    assert item["mask"].dtype == torch.uint8 and int(item["mask"].max()) <= 2
    assert item["params"]["species"] in ("standin_a", "standin_b")
    loader = torch.utils.data.DataLoader(ViewsDataset(path, outputs=["sketch_tsn"]), batch_size=4)
    assert next(iter(loader))["sketch_tsn"].shape == (4, 1, SIZE, SIZE)


def test_hugging_face_datasets_reads_the_views_with_8_bit_maps_as_images(standin_dataset, tmp_path):
    from PIL import Image

    from farm.dataset.image_codec import decode_map

    _, path = standin_dataset
    views = dataset.to_huggingface(path, "views", cache_dir=str(tmp_path / "hf"))
    assert views.num_rows == 10
    row = views[0]
    assert isinstance(row["sketch_tsn"], Image.Image) and row["sketch_tsn"].size == (SIZE, SIZE)
    assert isinstance(row["mask"], Image.Image) and int(np.asarray(row["mask"]).max()) <= 2
    depth = decode_map(row["depth"], row["depth_scale"], row["depth_offset"])
    assert depth.shape == (SIZE, SIZE) and depth.max() > 0
    trees = dataset.to_huggingface(path, "trees", cache_dir=str(tmp_path / "hf"))
    assert sorted(trees["index"]) == list(range(6))


def test_manifest_counts_failures_and_checksums_every_part(standin_dataset):
    spec, path = standin_dataset
    manifest = dataset.read_manifest(path)
    assert manifest["counts"] == {"trees": 6, "views": 10, "failed": 1, "shards": spec.n_shards}
    assert manifest["failures"][0]["species"] == "broken"
    assert all(len(s[t]["sha256"]) == 64 for s in manifest["shards"] for t in ("trees", "views"))
    assert json.loads(json.dumps(manifest)) == manifest


# ------------------------------------------------------------------------------------------ read_columns
def test_read_columns_reads_only_the_asked_columns_in_part_order(standin_dataset):
    spec, path = standin_dataset
    trees = dataset.read_columns(path, "trees", ["index", "species"])
    assert trees.column_names == ["index", "species"]
    assert trees["index"].to_pylist() == list(range(spec.n_trees))  # shard by shard, rows in shard order
    views = dataset.read_columns(path, "views", ["tree_id", "view", "depth_scale"])
    assert views.column_names == ["tree_id", "view", "depth_scale"] and views.num_rows == 10
    keys = list(zip(views["tree_id"].to_pylist(), views["view"].to_pylist()))
    assert keys == sorted(keys)


def test_read_columns_keeps_the_rows_a_filter_matches(standin_dataset):
    import pyarrow.compute as pc

    _, path = standin_dataset
    last = dataset.read_columns(path, "views", ["tree_id"])["tree_id"][-1].as_py()
    one = dataset.read_columns(path, "views", ["tree_id", "view"], filters=pc.field("tree_id") == last,
                               memory_map=True)
    assert one.to_pylist() == [{"tree_id": last, "view": 0}, {"tree_id": last, "view": 1}]


def test_read_columns_names_a_damaged_part_file(standin_dataset, tmp_path):
    import shutil

    _, path = standin_dataset
    copy = tmp_path / "damaged"
    shutil.copytree(path, copy)
    part = copy / "views/part-00001.parquet"
    part.write_bytes(part.read_bytes()[:200])
    with pytest.raises(dataset.DatasetError, match=r"part file .*views/part-00001\.parquet cannot be read"):
        dataset.read_columns(str(copy), "views", ["tree_id"])
    assert dataset.read_columns(str(copy), "trees", ["tree_id"]).num_rows == 6  # the other table still reads


def test_read_columns_refuses_an_unknown_table(standin_dataset):
    _, path = standin_dataset
    with pytest.raises(dataset.DatasetError, match="unknown table 'leaves'; known: trees, views"):
        dataset.read_columns(path, "leaves", ["tree_id"])


def test_inspect_s_table_keeps_its_columns_under_a_long_species_name(tmp_path, ray_session):
    from farm.commands.inspect import summary_table

    long_name = "standin_with_a_long_preset_name"
    spec = standin_spec(species={"standin_a": 1, long_name: 1})
    run_job(spec, str(tmp_path), workers=1, builder_factory=StandinChain, progress=False)
    lines = summary_table(str(tmp_path)).splitlines()
    assert len(lines) == 3 and len({len(line) for line in lines}) == 1, lines  # every column lines up
    assert lines[2].startswith(f"{long_name} ")
