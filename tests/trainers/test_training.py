"""Training on Ray Train end to end, on tiny datasets and tiny networks: the CLI, resume after a crash, the
registry, retraining's promotion rule, a predictor in a fresh process, and bad input."""
from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from farm import pipeline
from farm.cli import main as farm_main
from trainers import models as trained_models
from trainers.curves import read_metrics_csv
from trainers.networks import SettingsError, TrainSettings, schedule_factor
from trainers.model_tables import below_baseline
from trainers.registry import RegistryError, open_registry
from trainers.tasks import TASKS
from trainers.training import TrainingError, train

ROOT = Path(__file__).resolve().parents[2]
FARM = [sys.executable, "-m", "farm.cli"]
torch.set_num_threads(1)
TINY = {"pix2pix-trunk": dict(width=4, batch_size=8), "sketchnet": dict(width=0.25, depth=0.34, batch_size=8)}

pytestmark = pytest.mark.slow


def _env(tmp_path: Path) -> dict:
    return {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT)}


# ------------------------------------------------------------------------------------------ the CLI
def test_farm_train_trains_registers_and_lists(training_datasets, tmp_path, capsys, monkeypatch):
    # In this process, on the tests' Ray: a subprocess would start a Ray of its own for each command.
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.chdir(tmp_path)
    registry = tmp_path / "registry"
    code = farm_main(["train", "pix2pix-trunk", "--data", str(training_datasets["pix2pix-trunk"]), "--epochs", "1",
                      "--width", "4", "--batch-size", "8", "--models", str(registry), "--quiet",
                      "--run-dir", str(tmp_path / "run"), "--force"])
    run = capsys.readouterr()
    assert code == 0, run.err[-3000:]
    # --force: champion even if one tiny epoch scores worse than the baseline, which a warning line then says
    assert "registered pix2pix-trunk v1 (champion, latest)" in run.out
    if below_baseline(open_registry(registry).version("pix2pix-trunk", 1)):
        assert "warning: pix2pix-trunk v1 is worse than its baseline: depth_error" in run.err
    assert "depth_error" in run.out
    rows = read_metrics_csv(tmp_path / "run" / "metrics.csv")
    assert [r["epoch"] for r in rows] == [0] and all(np.isfinite(r["val_depth_error"]) for r in rows)
    assert (tmp_path / "run" / "curves.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    code = farm_main(["models", "list", "--models", str(registry)])
    listing = capsys.readouterr()
    assert code == 0 and "pix2pix-trunk" in listing.out and "v1" in listing.out
    version = open_registry(registry).champion("pix2pix-trunk")
    assert {"depth_error", "depth_error_baseline"} <= set(version.metrics)
    assert version.tags["task"] == "pix2pix-trunk" and version.tags["code_version"]
    split = open_registry(registry).load_json("pix2pix-trunk", "champion", "split")
    assert split["test"], "the held-out split is stored with the model"

    # A predictor in a fresh process, without Ray: the ONNX file through ONNX Runtime.
    code = ("import sys, numpy as np; from trainers.models import load; "
            f"p = load('pix2pix-trunk', {str(registry)!r}); "
            "img = np.full((300, 200, 3), 255, np.uint8); img[40:260, 95:105] = (200, 30, 30); "
            "d = p.predict(img); assert d.shape == (1, 256, 256), d.shape; "
            "assert 0 <= d.min() and d.max() <= 1; assert 'ray' not in sys.modules; print('ok')")
    fresh = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=_env(tmp_path), capture_output=True,
                           text=True, timeout=120)
    assert fresh.returncode == 0 and fresh.stdout.strip() == "ok", fresh.stderr[-2000:]

    # farm retrain as a scheduled job runs it: a challenger from the champion, the report, the registry updated.
    code = farm_main(["retrain", "pix2pix-trunk", "--data", str(training_datasets["pix2pix-trunk"]), "--epochs", "1",
                      "--models", str(registry), "--quiet", "--report", str(tmp_path / "report")])
    retrained = capsys.readouterr()
    assert code == 0, retrained.err[-3000:]
    report = json.loads((tmp_path / "report" / "retrain-report.json").read_text())
    assert report["champion_version"] == 1 and isinstance(report["promoted"], bool)
    assert (tmp_path / "report" / "retrain-report.md").read_text().startswith("# Retraining pix2pix-trunk")
    after = open_registry(registry)
    assert after.latest("pix2pix-trunk").version == 2
    assert after.champion("pix2pix-trunk").version == (2 if report["promoted"] else 1)


def test_print_data_spec_is_the_shipped_spec():
    run = subprocess.run(FARM + ["train", "sketchnet", "--print-data-spec"], capture_output=True, text=True,
                         timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0 and run.stdout == TASKS["sketchnet"].spec_path.read_text()


@pytest.mark.parametrize("args, fragment", [
    (["train", "pix2pix-trunk", "--data", "{empty}"], "empty"),
    (["train", "pix2pix-trunk", "--data", "{sketchnet}"], "trunk_strokes"),
    (["train", "pix2pix-trunk"], "--data"),
    (["train", "pix2pix-trunk", "--data", "{trunk}", "--models", "{file}/registry"], "registry"),
    (["train", "pix2pix-trunk", "--data", "{trunk}", "--epochs", "0"], "epochs"),
    (["models", "show", "nope", "--models", "{registry}"], "holds no model registry"),
    (["models", "list", "--models", "{empty}"], "holds no model registry"),
    (["train", "sketchnet", "--data", "{sketchnet}"], "0 in validation and 0 in test"),
])
def test_bad_input_is_one_line_and_exit_2(training_datasets, tmp_path, args, fragment, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "empty").mkdir()
    (tmp_path / "file").write_text("not a folder")
    names = {"empty": tmp_path / "empty", "sketchnet": training_datasets["sketchnet"],
             "trunk": training_datasets["pix2pix-trunk"],
             "file": tmp_path / "file", "registry": tmp_path / "registry"}
    argv = [a.format(**{k: str(v) for k, v in names.items()}) for a in args]
    try:
        code = farm_main(argv)
    except SystemExit as exit_:  # argparse's own refusals
        code = exit_.code
    stderr = capsys.readouterr().err
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert code == 2, stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("farm: error:") and fragment in lines[0], stderr
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_too_few_trees_are_refused_before_ray_starts_with_the_trees_of_each_part(training_datasets, tmp_path,
                                                                                 capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)

    def no_ray(*args, **kwargs):
        raise AssertionError("Ray was started for data too small to train on")

    monkeypatch.setattr(pipeline, "ray_connection", no_ray)
    assert farm_main(["train", "sketchnet", "--data", str(training_datasets["sketchnet"]), "--quiet"]) == 2
    line = capsys.readouterr().err.strip()
    # The tiny dataset's 4 trees all hash into train; the line says so, and how many trees the shipped spec needs.
    assert "puts 4 of the 4 usable trees in train, 0 in validation and 0 in test" in line
    assert f"from {TASKS['sketchnet'].min_trees} trees" in line and "\n" not in line
    assert list(tmp_path.iterdir()) == []  # no run folder, no registry


# ------------------------------------------------------------------------------------------ resume
@pytest.fixture(scope="module")
def trunk_run(training_datasets, tmp_path_factory):
    """An uninterrupted two-epoch pix2pix-trunk run, its learning rate on the cosine schedule (set from the step
    count, so a resumed run must continue the same curve)."""
    settings = TrainSettings(epochs=2, schedule="cosine", **TINY["pix2pix-trunk"])
    return train("pix2pix-trunk", [str(training_datasets["pix2pix-trunk"])], settings=settings,
                 run_dir=tmp_path_factory.mktemp("trunk-run") / "run")


def test_a_crashed_run_resumes_at_its_step_with_the_same_losses(training_datasets, trunk_run, tmp_path):
    settings = trunk_run.network.settings
    data = [str(training_datasets["pix2pix-trunk"])]
    with pytest.raises(Exception, match="injected crash after epoch 0"):
        train("pix2pix-trunk", data, settings=settings, run_dir=tmp_path / "crashed", crash_after_epoch=0)
    assert [r["epoch"] for r in read_metrics_csv(tmp_path / "crashed" / "metrics.csv")] == [0]
    shutil.copytree(tmp_path / "crashed", tmp_path / "corrupt")
    resumed = train("pix2pix-trunk", data, settings=settings, run_dir=tmp_path / "crashed")
    assert resumed.resumed_from_epoch == 0
    assert resumed.steps == trunk_run.steps and resumed.epochs == trunk_run.epochs == 2
    for a, b in zip(trunk_run.history, resumed.history):
        assert a["step"] == b["step"] and a["train_loss"] == b["train_loss"], (a, b)
        assert a["val_depth_error"] == b["val_depth_error"]
    assert resumed.test_metrics == trunk_run.test_metrics
    # A run folder is kept to its own settings.
    with pytest.raises(TrainingError, match="another run"):
        train("pix2pix-trunk", data, settings=dataclasses.replace(settings, seed=5), run_dir=tmp_path / "crashed")
    # A damaged checkpoint is a clear error, not a traceback from torch.
    for state in (tmp_path / "corrupt").rglob("state.pt"):
        state.write_bytes(b"not a checkpoint")
    with pytest.raises(TrainingError, match="checkpoint .* cannot be read"):
        train("pix2pix-trunk", data, settings=settings, run_dir=tmp_path / "corrupt")


def test_two_workers_train_data_parallel(training_datasets, tmp_path):
    """Two DDP workers on two CPUs finish (they used to wait forever: Ray Data had no CPU left, and rank 0 took
    DDP off its own modules) and each steps half the views."""
    settings = TrainSettings(epochs=1, **TINY["pix2pix-trunk"])
    result = train("pix2pix-trunk", [str(training_datasets["pix2pix-trunk"])], settings=settings,
                   run_dir=tmp_path / "run", workers=2)
    views = result.summary["views"]["train"]
    assert result.epochs == 1
    assert result.steps == -(-(views // 2) // settings.batch_size)
    assert np.isfinite(result.test_metrics["depth_error"])


# ------------------------------------------------------------------------------------------ retraining
def test_retrain_promotes_a_better_challenger_and_keeps_the_champion_against_a_worse(training_datasets, trunk_run,
                                                                                    tmp_path, monkeypatch):
    registry = open_registry(tmp_path / "registry")
    data = [str(training_datasets["pix2pix-trunk"])]
    settings = TrainSettings(epochs=1, **TINY["pix2pix-trunk"])
    champion = trained_models.register_result(registry, trunk_run, code_version="test", force=True)
    assert champion.is_champion and champion.version == 1
    primary = trunk_run.network.primary
    unbeatable = 1e9 if trunk_run.network.higher_is_better else -1e9

    # The champion scored (on the champion's own held-out split) just above whatever the challenger reaches.
    real_score = trained_models._score_folder
    monkeypatch.setattr(trained_models, "_score_folder", lambda folder, task, batches: {
        **real_score(folder, task, batches), primary: unbeatable})
    kept = trained_models.retrain("pix2pix-trunk", data, registry, run_dir=tmp_path / "worse", settings=settings)
    assert not kept.promoted and "champion stays" in kept.reason
    assert registry.champion("pix2pix-trunk").version == 1 and registry.latest("pix2pix-trunk").version == 2
    report = json.loads((tmp_path / "worse" / "retrain-report.json").read_text())
    assert report["promoted"] is False and report["champion_version"] == 1
    assert (tmp_path / "worse" / "retrain-report.md").read_text().startswith(
        "# Retraining pix2pix-trunk: champion kept")

    monkeypatch.setattr(trained_models, "_score_folder", lambda folder, task, batches: {
        **real_score(folder, task, batches), primary: -unbeatable})
    better = trained_models.retrain("pix2pix-trunk", data, registry, run_dir=tmp_path / "better", settings=settings)
    assert better.promoted and registry.champion("pix2pix-trunk").version == 3
    # The challenger was scored on the champion's frozen held-out split.
    assert registry.load_json("pix2pix-trunk", 3, "split")["test"] == \
        registry.load_json("pix2pix-trunk", 1, "split")["test"]
    # And a predictor of the new champion gives a depth map of a drawing.
    predictor = trained_models.load("pix2pix-trunk", registry)
    drawing = np.full((320, 240, 3), 255, np.uint8)
    drawing[40:300, 115:125] = (200, 30, 30)
    depth = predictor.predict(drawing)
    assert depth.shape == (1, 256, 256) and np.isfinite(depth).all() and 0 <= depth.min() <= depth.max() <= 1


def test_a_failed_registration_leaves_nothing(trunk_run, tmp_path, monkeypatch):
    registry = open_registry(tmp_path / "registry")
    monkeypatch.setattr(type(trunk_run.network), "export", lambda self, folder: (_ for _ in ()).throw(
        OSError("disk full")))
    with pytest.raises(OSError, match="disk full"):
        trained_models.register_result(registry, trunk_run)
    assert registry.names() == [] and registry.champion("pix2pix-trunk") is None


def test_the_cosine_schedule_falls_from_the_rate_to_zero():
    steps = np.arange(11)
    factors = np.array([schedule_factor("cosine", int(s), 10) for s in steps])
    assert factors[0] == 1.0 and abs(factors[-1]) < 1e-12 and abs(factors[5] - 0.5) < 1e-12
    assert np.all(np.diff(factors) < 0)
    assert {schedule_factor("constant", int(s), 10) for s in steps} == {1.0}
    with pytest.raises(SettingsError, match="schedule"):
        TrainSettings(schedule="linear")


def test_settings_and_missing_models_are_refused():
    with pytest.raises(SettingsError, match="batch_size"):
        TrainSettings(batch_size=0)
    with pytest.raises(SettingsError, match="unknown"):
        TrainSettings.from_dict({"epochs": 2, "widht": 3})
    with pytest.raises((RegistryError, trained_models.ModelFilesError)):
        trained_models.predictor_from_folder(ROOT / "docs")


@pytest.mark.parametrize("task", list(TASKS))
def test_the_shipped_default_models_load_and_predict(task):
    """models/ (make models) loads without a registry; its outputs have the task's shapes and ranges."""
    import species

    predictor = trained_models.load(task)
    drawing = np.full((400, 300, 3), 255, np.uint8)
    drawing[60:360, 145:155] = (40, 40, 40) if task != "pix2pix-trunk" else (200, 30, 30)
    drawing[150:160, 80:220] = drawing[60, 145]
    out = predictor.predict(drawing if task == "pix2pix-trunk" else drawing[..., 0])
    if task == "sketchnet":
        assert out["species"] in TASKS["sketchnet"].spec_path.read_text()
        assert species.grow(out, np.random.default_rng(0)).n_nodes > 1
    else:
        channels, size = TASKS[task].out_channels, TASKS[task].input_size
        assert out.shape == (channels, size, size) and 0.0 <= out.min() and out.max() <= 1.0
