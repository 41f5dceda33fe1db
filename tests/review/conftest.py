"""Review test fixtures: one small dataset made by the real pipeline, and review servers started on free ports.

The dataset (3 presets x 2 trees, 64 px, tsn4 rig, depth + sketch) is made once per test run on the shared Ray.
"""
from __future__ import annotations

import shutil
from contextlib import contextmanager
from pathlib import Path

import pytest

from farm.jobs import parse_spec
from farm.pipeline import run_job
from farm.review.server import ReviewServer, create_app, new_token
from farm.review.service import ReviewService

SPEC = {"name": "review", "seed": 3, "species": {"sc_dome_shrub": 2, "lsystem_bush": 2, "palm": 2},
        "shard_size": 4, "render": {"rig": "tsn4", "size": 64, "outputs": ["depth", "sketch_tsn"]}}


@pytest.fixture(scope="session")
def review_dataset(tmp_path_factory, ray_session) -> Path:
    """A finished 6-tree dataset in 2 shards (treat as read-only; copy it to change it)."""
    out = tmp_path_factory.mktemp("review") / "dataset"
    run_job(parse_spec(SPEC), str(out), workers=2, progress=False)
    return out


@pytest.fixture
def dataset_copy(review_dataset, tmp_path) -> Path:
    """A private copy of the dataset (for tests that write reviews.sqlite or parts beside it)."""
    copy = tmp_path / "dataset"
    shutil.copytree(review_dataset, copy)
    return copy


@contextmanager
def running_server(dataset: Path, db: Path, token: str | None = None):
    """A review server on a free localhost port: yields (base URL, token, service)."""
    token = token or new_token()
    service = ReviewService(str(dataset), db)
    server = ReviewServer(create_app(service, token), "127.0.0.1", 0).start()
    try:
        yield server.base, token, service
    finally:
        server.stop()


@pytest.fixture
def server(review_dataset, tmp_path):
    """(base URL, token, service) of a server over the shared dataset with a fresh reviews database."""
    with running_server(review_dataset, tmp_path / "reviews.sqlite") as running:
        yield running
