"""The training tasks are one registry: a throwaway task, one entry in `trainers.tasks.TASKS`, reaches every place
that lists or looks up tasks: `farm train`'s choices, help and --print-data-spec, the training loop (in Ray Train's
workers too, which see the task record, not this process's registry), the model registry and `farm models`, the
predictor, and bench_train's task list and recipe. A place that kept its own list of tasks would refuse it."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from benchmarks import bench_train
from farm.cli import build_parser
from farm.cli import main as farm_main
from farm.jobs import load_spec
from farm.tree_chain import tree_id
from trainers import models as trained_models
from trainers.data import Split
from trainers.registry import open_registry
from trainers.tasks import TASKS, Task, TrainingDataError, get_task

torch.set_num_threads(1)

# A depth network on the trunk pairs under a name, model name and recipe no other place knows.
THROWAWAY = Task("throwaway-depth", inputs=("trunk_strokes",), styles=(), targets=("trunk_depth",),
                 input_kind="strokes", input_size=256, spec_name="pix2pix-trunk", model_name="throwaway-depth-model",
                 network="pix2pix", rigs=("two-view",), recipe={"width": 4, "batch_size": 8, "epochs": 1},
                 channel_names=("depth",), depth_channels=(0,))


@pytest.fixture
def throwaway(monkeypatch) -> Task:
    monkeypatch.setitem(TASKS, THROWAWAY.name, THROWAWAY)
    return THROWAWAY


def test_a_task_names_a_known_network_and_pix2pix_its_target_channels():
    with pytest.raises(TrainingDataError, match="network 'gan' is unknown: allowed sketchnet, pix2pix, segment"):
        Task("x", ("sketch_edges",), (), ("trunk_depth",), "sketch", 256, "pix2pix-trunk", "x", network="gan")
    with pytest.raises(TrainingDataError, match="names its target output and the target's channels"):
        Task("x", ("sketch_edges",), (), ("trunk_depth",), "sketch", 256, "pix2pix-trunk", "x", network="pix2pix")
    with pytest.raises(TrainingDataError, match="'throwaway-depth' is unknown: allowed sketchnet, "
                                                "pix2pix-silhouette, pix2pix-trunk, tree-mask"):
        get_task(THROWAWAY.name)


def test_farm_train_and_retrain_offer_it_in_their_choices_and_help(throwaway, capsys):
    for command in ("train", "retrain"):
        assert build_parser().parse_args([command, throwaway.name]).task == throwaway.name
        with pytest.raises(SystemExit) as exit_:
            farm_main([command, "--help"])
        assert exit_.value.code == 0
        help_text = capsys.readouterr().out
        assert "{sketchnet,pix2pix-silhouette,pix2pix-trunk,tree-mask,throwaway-depth}" in help_text
        assert "TASK is sketchnet, pix2pix-silhouette, pix2pix-trunk, tree-mask or throwaway-depth." in help_text


def test_farm_train_prints_its_data_spec(throwaway, capsys):
    assert farm_main(["train", throwaway.name, "--print-data-spec"]) == 0
    assert capsys.readouterr().out == throwaway.spec_path.read_text()


@pytest.mark.slow
def test_farm_train_trains_it_registers_its_model_and_farm_models_lists_it(throwaway, training_datasets, tmp_path,
                                                                           capsys, monkeypatch):
    # In this process, where the registry holds the throwaway entry; Ray Train's workers get the task record.
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    registry = tmp_path / "registry"
    code = farm_main(["train", throwaway.name, "--data", str(training_datasets["pix2pix-trunk"]), "--epochs", "1",
                      "--width", "4", "--batch-size", "8", "--models", str(registry), "--quiet",
                      "--run-dir", str(tmp_path / "run"), "--force"])  # champion even below the baseline
    out = capsys.readouterr().out
    assert code == 0
    assert out.startswith("throwaway-depth: 1 epoch, ") and "depth_error" in out
    assert "registered throwaway-depth-model v1 (champion, latest)" in out
    assert json.loads((tmp_path / "run" / "settings.json").read_text())["task"] == throwaway.name

    assert farm_main(["models", "list", "--models", str(registry)]) == 0
    assert "throwaway-depth-model" in capsys.readouterr().out
    assert farm_main(["models", "show", "throwaway-depth-model", "--models", str(registry)]) == 0
    assert "v1" in capsys.readouterr().out
    assert open_registry(registry).champion("throwaway-depth-model").tags["task"] == throwaway.name

    predictor = trained_models.load(throwaway.name, registry)
    drawing = np.full((300, 200, 3), 255, np.uint8)
    drawing[40:260, 95:105] = (200, 30, 30)
    depth = predictor.predict(drawing)
    assert depth.shape == (1, 256, 256) and 0 <= depth.min() <= depth.max() <= 1


@pytest.mark.slow
def test_bench_train_lists_it_and_trains_it_on_its_recipe(throwaway, training_datasets, tmp_path, capsys):
    assert bench_train.option_parser().parse_args([]).tasks.split(",") == list(TASKS)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / throwaway.name).symlink_to(training_datasets["pix2pix-trunk"])
    bench_train.main(["--data-root", str(tmp_path / "data"), "--tasks", throwaway.name, "--skip-throughput",
                      "--budget", "0", "--work", str(tmp_path / "work"), "--no-results"])
    assert "throwaway-depth" in capsys.readouterr().out
    [report] = json.loads((tmp_path / "work" / "bench_train.json").read_text())
    assert report["task"] == throwaway.name and report["epochs"] == throwaway.recipe["epochs"]
    assert np.isfinite(report["test"]["depth_error"])


@pytest.mark.parametrize("task", list(TASKS))
def test_min_trees_is_where_the_shipped_spec_first_fills_every_part_of_the_split(task):
    """`Task.min_trees` is right: the shipped spec with that many trees, and with each larger count (checked to a
    few hundred trees), puts a tree in train, validation and test; with one tree fewer it does not."""
    shipped = load_spec(TASKS[task].spec_path)

    def fills_every_part(trees: int) -> bool:
        spec = shipped.with_trees(trees)
        split = Split.by_hash([(spec.digest(), tree_id(spec.name, i)) for i in range(trees)])
        return all(split.parts[part] for part in ("train", "val", "test"))

    least = TASKS[task].min_trees
    assert not fills_every_part(least - 1)
    assert all(fills_every_part(n) for n in range(least, least + 200))
