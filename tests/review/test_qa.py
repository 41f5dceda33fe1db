"""Automatic QA flags: each check raised by a crafted bad tree and silent on the real ones; cached per batch."""
from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import farm.dataset as dataset
from farm.review import qa
from farm.review.index import DatasetIndex
from farm.review.service import ReviewService, TreeQuery
from farm.dataset.storage import sha256_hex


@pytest.fixture(scope="module")
def real_trees(review_dataset) -> pa.Table:
    return dataset.open(str(review_dataset)).to_table(columns=qa.TREE_COLUMNS)


def crafted(table: pa.Table, row: int, **changes) -> pa.Table:
    """`table` with one row's columns replaced (lists as Python lists)."""
    rows = table.to_pylist()
    rows[row].update(changes)
    return pa.Table.from_pylist(rows, schema=table.schema)


def flags_of(table: pa.Table) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for tree_id, flag, value in qa.tree_flags(table).rows():
        out.setdefault(tree_id, {})[flag] = value
    return out


def test_real_trees_raise_no_tree_flags(real_trees):
    assert flags_of(real_trees) == {}


def test_real_sketches_have_ink(review_dataset):
    views = dataset.open(str(review_dataset), "views").to_table(columns=["tree_id", "sketch_tsn"])
    assert qa.ink_flags(views["tree_id"].to_pylist(), views["sketch_tsn"].to_pylist()).rows() == []


def test_a_branch_below_ground_is_flagged_with_its_depth(real_trees):
    positions = np.array(real_trees["positions"][1].as_py()).reshape(-1, 3)
    positions[-1, 2] = -0.8
    flags = flags_of(crafted(real_trees, 1, positions=positions.ravel().tolist()))
    assert list(flags) == [real_trees["tree_id"][1].as_py()]
    assert flags[real_trees["tree_id"][1].as_py()]["below_ground"] == pytest.approx(-0.8)


def test_a_leaf_far_outside_the_crown_is_flagged_and_counted(real_trees):
    leaves = np.array(real_trees["leaves"][0].as_py()).reshape(-1, 4, 4)
    leaves[[3, 7], 0, 3] += 10.0 * real_trees["height"][0].as_py()
    flags = flags_of(crafted(real_trees, 0, leaves=leaves.ravel().tolist()))
    assert flags == {real_trees["tree_id"][0].as_py(): {"leaves_outside_crown": 2.0}}


def test_a_detached_part_or_a_second_root_is_flagged_disconnected(real_trees):
    positions = np.array(real_trees["positions"][2].as_py()).reshape(-1, 3)
    parent = np.array(real_trees["parent"][2].as_py())
    last = len(parent) - 1
    positions[last] += [0.0, 0.0, 3.0 * real_trees["height"][2].as_py()]  # one node flung far from its parent
    parent[last - 1] = -1  # and a second root
    table = crafted(real_trees, 2, positions=positions.ravel().tolist(), parent=parent.tolist())
    assert flags_of(table)[real_trees["tree_id"][2].as_py()]["disconnected"] >= 2


def test_a_mesh_without_triangles_or_a_failed_build_is_degenerate(real_trees):
    table = crafted(crafted(real_trees, 3, bark_triangles=0, leaf_triangles=0), 4, error="ValueError: boom")
    flags = flags_of(table)
    assert set(flags) == {real_trees["tree_id"][3].as_py(), real_trees["tree_id"][4].as_py()}
    assert all("degenerate_mesh" in f for f in flags.values())


def test_a_mesh_with_millions_of_triangles_is_huge(real_trees):
    flags = flags_of(crafted(real_trees, 5, bark_triangles=3_000_000))
    assert flags == {real_trees["tree_id"][5].as_py(): {"huge_mesh": pytest.approx(
        3_000_000 + real_trees["leaf_triangles"][5].as_py())}}


def test_a_blank_sketch_is_faint_and_a_drawn_one_is_not(review_dataset):
    from farm.dataset.image_codec import encode_map

    blank = encode_map("sketch_tsn", np.full((64, 64), 255, np.uint8))[0]
    drawn = np.full((64, 64), 255, np.uint8)
    drawn[10:50, 30:33] = 0
    flags = qa.ink_flags(["a", "a", "b"], [blank, encode_map("sketch_tsn", drawn)[0], encode_map("sketch_tsn", drawn)[0]])
    assert flags.rows() == [("a", "faint_sketch", 0.0)]


def test_flags_are_computed_once_per_batch_and_read_from_the_database_after(dataset_copy, monkeypatch):
    # Craft a bad tree into shard 0 (below ground), keeping the manifest's checksum right.
    part = dataset_copy / "trees/part-00000.parquet"
    table = pq.read_table(part)
    positions = np.array(table["positions"][0].as_py()).reshape(-1, 3)
    positions[5, 2] = -1.0
    data = dataset.serialize_table(crafted(table, 0, positions=positions.ravel().tolist()).to_pylist(),
                                   dataset.trees_schema())
    part.write_bytes(data)
    manifest = json.loads((dataset_copy / "manifest.json").read_text())
    manifest["shards"][0]["trees"].update(sha256=sha256_hex(data), bytes=len(data))
    (dataset_copy / "manifest.json").write_text(json.dumps(manifest))

    first = ReviewService(str(dataset_copy))
    assert first.qa == {"review-00000000": {"below_ground": -1.0}}
    listed = first.list_trees(TreeQuery({"flag": "below_ground"}))["trees"]
    assert [t["tree_id"] for t in listed] == ["review-00000000"] and listed[0]["flags"] == {"below_ground": -1.0}

    def no_recompute(self, batch):
        raise AssertionError(f"QA flags of {batch['id']} computed again")

    monkeypatch.setattr(DatasetIndex, "compute_qa", no_recompute)
    assert ReviewService(str(dataset_copy)).qa == first.qa
