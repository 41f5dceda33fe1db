"""Fixtures of the training tests: tiny datasets of the shipped specs, made once per test run."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from farm.jobs import load_spec
from farm.pipeline import run_job
from trainers.tasks import TASKS


def _tiny_spec(name: str, trees: int):
    spec = load_spec(TASKS[name].spec_path).with_trees(trees)
    return dataclasses.replace(spec, render=dataclasses.replace(spec.render, size=64), shard_size=4)


@pytest.fixture(scope="session")
def training_datasets(tmp_path_factory, ray_session) -> dict[str, Path]:
    """A 24-tree pix2pix-trunk dataset at 64 px (enough for a tree in each split part), and a 4-tree sketchnet one
    (it only has to lack the trunk strokes)."""
    root = tmp_path_factory.mktemp("training-data")
    out = {}
    for name, trees in (("pix2pix-trunk", 24), ("sketchnet", 4)):
        out[name] = root / name
        run_job(_tiny_spec(name, trees), str(out[name]), workers=2, progress=False)
    return out
