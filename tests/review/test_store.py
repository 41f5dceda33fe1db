"""The verdict store (SQLite, WAL) and its Parquet export: upsert per (reviewer, tree), rejections, join by tree_id."""
from __future__ import annotations

import sqlite3

import pyarrow.parquet as pq
import pytest

import farm.dataset as dataset
from farm.review.export import REVIEWS_PART, export_reviews
from farm.review.store import ReviewError, ReviewStore, check_verdict


def test_the_database_runs_in_wal_mode(tmp_path):
    ReviewStore(tmp_path / "r.sqlite")
    with sqlite3.connect(tmp_path / "r.sqlite") as connection:
        assert connection.execute("PRAGMA journal_mode").fetchone()[0] == "wal"


def test_a_second_verdict_by_the_same_reviewer_replaces_the_first(tmp_path):
    store = ReviewStore(tmp_path / "r.sqlite")
    store.put_verdict("t1", "ann", "approve", time_ms=1)
    store.put_verdict("t1", "ann", "flag", "leaves float", time_ms=2)
    store.put_verdict("t1", "bob", "reject", time_ms=3)
    assert [(v["reviewer"], v["verdict"], v["note"]) for v in store.verdicts("t1")] == \
        [("ann", "flag", "leaves float"), ("bob", "reject", "")]
    assert store.verdict_summary() == {"t1": {"flag": 1, "reject": 1}}


@pytest.mark.parametrize("body, named", [({"tree_id": "t", "reviewer": " ", "verdict": "approve"}, "reviewer"),
                                         ({"tree_id": "t", "reviewer": "a", "verdict": "ok"}, "approve, reject, flag"),
                                         ({"tree_id": "t", "reviewer": "a", "verdict": "approve", "x": 1}, "x"),
                                         ({"tree_id": "t", "reviewer": "a", "verdict": "approve", "note": 5}, "note")])
def test_check_verdict_names_the_bad_field(body, named):
    with pytest.raises(ReviewError, match=named):
        check_verdict(body)


def test_export_writes_one_row_per_verdict_joinable_with_the_trees_table(review_dataset, tmp_path):
    import shutil

    copy = tmp_path / "dataset"
    shutil.copytree(review_dataset, copy)
    store = ReviewStore(copy / "reviews.sqlite")
    store.put_verdict("review-00000001", "ann", "approve", time_ms=1_700_000_000_000)
    store.put_verdict("review-00000004", "ann", "reject", "no leaves", time_ms=1_700_000_001_000)
    path, rows = export_reviews(str(copy), store)
    assert rows == 2 and path.endswith(REVIEWS_PART)
    reviews = pq.read_table(copy / REVIEWS_PART)
    assert reviews.schema.field("time").type.tz == "UTC"
    joined = dataset.open(str(copy)).to_table(columns=["tree_id", "species"]).join(reviews, "tree_id", join_type="inner")
    assert sorted(joined.select(["tree_id", "verdict", "species"]).to_pylist(), key=lambda r: r["tree_id"]) == [
        {"tree_id": "review-00000001", "verdict": "approve", "species": "lsystem_bush"},
        {"tree_id": "review-00000004", "verdict": "reject", "species": "lsystem_bush"}]
