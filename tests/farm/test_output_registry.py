"""A render output registered as one `renderers.OUTPUTS` entry reaches the dataset: the pipeline's shard writer
stores its column (with `_scale`/`_offset` for a float map), and the readers decode it as the entry declares."""
from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

import farm.dataset as dataset
import renderers
from farm.dataset.image_codec import decode_map
from farm.dataset.manifest import build_manifest, validate_dataset, write_manifest
from farm.jobs import parse_spec
from farm.pipeline import plan_shards, run_shard
from farm.review.index import DatasetIndex
from farm.tree_chain import SpeciesChain
from renderers import Output

SIZE = 32
# Throwaway outputs made from what a view frame already has: a float map in [0, 1] (1 = near), a metric map
# (metres, 0 = background) and a uint8 map.
THROWAWAY = {
    "test_nearness": Output(lambda frame: (1.0 - frame.camera.depth01(frame.visible[0])).astype(np.float32),
                            np.float32),
    "test_metres": Output(lambda frame: np.where(frame.visible[0] > 0, frame.visible[0] + 1.0, 0.0).astype(np.float32),
                          np.float32, metric=True),
    "test_covered": Output(lambda frame: np.where(frame.visible[1] > 0, 255, 0).astype(np.uint8), np.uint8),
}
OUTPUTS = ["depth", *THROWAWAY]


@pytest.fixture(scope="module")
def registered():
    with pytest.MonkeyPatch.context() as patch:
        for name, output in THROWAWAY.items():
            patch.setitem(renderers.OUTPUTS, name, output)
        yield


@pytest.fixture(scope="module")
def throwaway_dataset(registered, tmp_path_factory):
    """A finished 2-tree dataset storing the throwaway outputs, written in this process by the pipeline's own
    shard writer and manifest (a Ray worker would not see the registration)."""
    spec = parse_spec({"name": "registry", "seed": 5, "species": {"sc_young_sapling": 1, "lsystem_monopodial": 1},
                       "shard_size": 1, "render": {"rig": "two-view", "size": SIZE, "outputs": OUTPUTS},
                       "store_glb": False})
    location = dataset.Location.resolve(str(tmp_path_factory.mktemp("registry")))
    chain = SpeciesChain(spec)
    try:
        records = {plan.shard: run_shard(spec, plan, location, chain) for plan in plan_shards(spec)}
    finally:
        chain.renderer().close()
    write_manifest(location, build_manifest(spec, records, wall_seconds=1.0))
    return location.root


def test_the_shard_writer_stores_each_output_with_scale_and_offset_for_the_float_maps(throwaway_dataset):
    schema = pq.read_schema(f"{throwaway_dataset}/views/part-00000.parquet")
    assert [n for n in schema.names if n.startswith("test_")] == [
        "test_nearness", "test_nearness_scale", "test_nearness_offset",
        "test_metres", "test_metres_scale", "test_metres_offset", "test_covered"]
    assert dataset.stored_float_outputs(throwaway_dataset) == {"depth", "test_nearness", "test_metres"}
    assert validate_dataset(throwaway_dataset) == []


def test_pyarrow_and_the_codec_read_the_maps_back_as_rendered(throwaway_dataset):
    views = dataset.open(throwaway_dataset, "views").to_table().to_pylist()
    assert len(views) == 4 and all(row["test_nearness_offset"] == 0.0 for row in views)
    for row in views:
        depth = decode_map(row["depth"], row["depth_scale"], row["depth_offset"])
        metres = decode_map(row["test_metres"], row["test_metres_scale"], row["test_metres_offset"])
        covered = decode_map(row["test_covered"])
        assert covered.dtype == np.uint8 and set(np.unique(covered)) == {0, 255}
        np.testing.assert_array_equal(metres == 0, depth == 0)
        assert np.abs(metres - np.where(depth > 0, depth + 1.0, 0.0)).max() <= row["test_metres_scale"] + row[
            "depth_scale"]


def test_the_torch_dataset_decodes_the_registered_outputs(throwaway_dataset):
    import torch

    item = dataset.ViewsDataset(throwaway_dataset, outputs=list(THROWAWAY))[1]
    assert item["test_nearness"].dtype == torch.float32 and item["test_nearness"].shape == (1, SIZE, SIZE)
    assert 0.0 <= float(item["test_nearness"].min()) and float(item["test_nearness"].max()) <= 1.0
    assert item["test_metres"].dtype == torch.float32 and float(item["test_metres"].min()) == 0.0
    assert float(item["test_metres"].max()) > 1.0
    assert item["test_covered"].dtype == torch.uint8 and int(item["test_covered"].max()) == 255


def test_the_review_index_shows_the_metric_map_near_bright_and_the_uint8_map_as_stored(throwaway_dataset):
    index = DatasetIndex(throwaway_dataset)
    tree_id = index.trees["tree_id"].iloc[0]
    row = dataset.read_columns(throwaway_dataset, "views", ["tree_id", "view", "test_covered"]).to_pylist()[0]
    assert index.view_image(row["tree_id"], row["view"], "test_covered") == row["test_covered"]
    shown = decode_map(index.view_image(tree_id, 0, "test_metres"))
    assert shown.dtype == np.uint8 and shown.max() == 255 and shown.min() == 0
