"""`farm review DIR` serves the dataset at a printed tokened URL; `farm review export DIR` writes the verdicts."""
from __future__ import annotations

import os
import re
import subprocess
import sys

import httpx
import pyarrow.parquet as pq

from farm.cli import main
from farm.review.store import ReviewStore


def test_farm_review_prints_a_localhost_url_with_a_token_that_opens_the_page(dataset_copy):
    process = subprocess.Popen([sys.executable, "-m", "farm.cli", "review", str(dataset_copy), "--port", "0"],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                               cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
    try:
        url = None
        for line in process.stdout:
            match = re.search(r"(http://127\.0\.0\.1:\d+/\?token=([A-Za-z0-9_-]+))", line)
            if match:
                url, token = match.groups()
                break
        assert url is not None
        assert httpx.get(url, timeout=10).status_code == 200
        assert httpx.get(url.split("?")[0], timeout=10).status_code == 401
        assert (dataset_copy / "reviews.sqlite").is_file()
    finally:
        process.terminate()
        process.wait(timeout=20)


def test_farm_review_export_writes_the_reviews_part(dataset_copy, capsys):
    ReviewStore(dataset_copy / "reviews.sqlite").put_verdict("review-00000003", "cli", "approve")
    assert main(["review", "export", str(dataset_copy)]) == 0
    assert "1 verdicts" in capsys.readouterr().out
    assert pq.read_table(dataset_copy / "reviews/part-00000.parquet")["tree_id"].to_pylist() == ["review-00000003"]


def test_a_bad_token_is_a_one_line_error(dataset_copy, capsys):
    assert main(["review", str(dataset_copy), "--token", "short"]) == 2
    assert capsys.readouterr().err.strip().startswith("farm: error: --token 'short' is invalid")


def test_review_of_a_folder_without_a_dataset_is_a_one_line_error(tmp_path, capsys):
    assert main(["review", "export", str(tmp_path)]) == 2
    assert "no manifest.json" in capsys.readouterr().err
