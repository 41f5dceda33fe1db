"""`farm models list|show` only read: no registry is created, nothing is written into the shipped models; the shipped
defaults are listed with their key metric; rows fit a terminal. A model worse than its baseline is said, and a first
version worse than its baseline is registered but not made champion unless forced."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

from farm.cli import main as farm_main
from trainers import models as trained_models
from trainers.model_tables import below_baseline, format_model_versions, format_models_table
from trainers.registry import CHAMPION, SHIPPED, open_registry
from trainers.tasks import TASKS

ROOT = Path(__file__).resolve().parents[2]
TERMINAL_COLUMNS = 100


def _snapshot(folder: Path) -> list[tuple[str, int, int]]:
    return sorted((str(p.relative_to(folder)), p.stat().st_size, p.stat().st_mtime_ns) for p in folder.rglob("*"))


def _stand_in_result(task: str, metric: float, baseline: float, files: dict[str, Path]):
    """What `register_result` reads of a training result, without training: the files come from `files`."""
    spec = TASKS[task]
    network = SimpleNamespace(task=spec, primary=spec.primary_metric, higher_is_better=spec.higher_is_better,
                              settings=SimpleNamespace(to_dict=lambda: {"epochs": 1}))
    return SimpleNamespace(network=network, split=SimpleNamespace(to_json=lambda: "{}"), files=files,
                           summary={"trees": {"train": 1, "val": 1, "test": 1}, "rejected": 0},
                           test_metrics={spec.primary_metric: metric},
                           baseline_metrics={spec.primary_metric: baseline}, history=[], epochs=1, steps=1)


@pytest.fixture(scope="module")
def registry_of_stand_ins(tmp_path_factory):
    """A registry for the module (creating one takes seconds; each test registers its own task's model), and
    `register(task, metric, baseline, **options)` registering a stand-in training result."""
    folder = tmp_path_factory.mktemp("stand-ins")
    weights = folder / "weights.pt"
    weights.write_bytes(b"weights")
    registry = open_registry(folder / "registry")

    def register(task: str, metric: float, baseline: float, **options):
        result = _stand_in_result(task, metric, baseline, {"weights.pt": weights})
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(trained_models, "model_files", lambda result, folder: dict(result.files))
            return trained_models.register_result(registry, result, datasets=[], **options)

    return registry, register


# ------------------------------------------------------------------------------------------ listing only reads
def test_models_list_without_a_registry_creates_none_and_lists_the_shipped_models(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert farm_main(["models", "list"]) == 0
    out = capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []  # no registry/ and no mlflow.sqlite
    for task in TASKS.values():
        row = next(line for line in out.splitlines() if line.startswith(f"{task.model_name} "))
        assert SHIPPED in row and task.primary_metric in row


def test_models_list_of_the_shipped_folder_writes_nothing_into_it(capsys):
    before = _snapshot(ROOT / "models")
    assert farm_main(["models", "list", "--models", str(ROOT / "models")]) == 0
    out = capsys.readouterr().out
    assert _snapshot(ROOT / "models") == before
    assert "no models" not in out and all(f"{name} " in out for name in TASKS)


def test_models_list_and_show_leave_a_registry_as_it_was(registry_of_stand_ins, capsys):
    registry, register = registry_of_stand_ins
    if registry.latest("pix2pix-silhouette") is None:
        register("pix2pix-silhouette", 0.1, 0.2)
    folder = Path(registry.label)
    before = _snapshot(folder)
    assert farm_main(["models", "list", "--models", str(folder)]) == 0
    assert farm_main(["models", "show", "pix2pix-silhouette", "--models", str(folder)]) == 0
    assert _snapshot(folder) == before
    assert "pix2pix-silhouette" in capsys.readouterr().out


def test_models_list_rows_fit_a_terminal_and_show_has_every_metric(capsys, monkeypatch, tmp_path):
    monkeypatch.chdir(tmp_path)
    assert farm_main(["models", "list"]) == 0
    listing = capsys.readouterr().out
    assert max(map(len, listing.splitlines())) <= TERMINAL_COLUMNS, listing
    assert "accuracy_species" not in listing
    assert farm_main(["models", "show", "sketchnet"]) == 0
    shown = capsys.readouterr().out
    assert "accuracy_species" in shown and "score_overall" in shown


# ------------------------------------------------------------------------------------------ worse than baseline
def test_a_first_version_worse_than_its_baseline_is_registered_but_not_champion(registry_of_stand_ins):
    registry, register = registry_of_stand_ins
    version = register("sketchnet", 71.97, 75.16)  # score_overall: higher is better
    assert version.version == 1 and CHAMPION not in version.aliases
    assert registry.champion("sketchnet") is None
    assert "worse than its baseline: score_overall 71.97 against the baseline's 75.16" in below_baseline(version)


def test_force_makes_a_first_version_worse_than_its_baseline_champion(registry_of_stand_ins):
    registry, register = registry_of_stand_ins
    assert CHAMPION in register("pix2pix-trunk", 0.3, 0.2, force=True).aliases  # depth_error: lower is better


def test_a_first_version_better_than_its_baseline_becomes_champion(registry_of_stand_ins):
    registry, register = registry_of_stand_ins
    if registry.latest("pix2pix-silhouette") is None:
        register("pix2pix-silhouette", 0.1, 0.2)  # depth_error: lower is better
    first = registry.version("pix2pix-silhouette", 1)
    assert first.is_champion and below_baseline(first) is None


def test_models_show_and_list_warn_of_a_version_worse_than_its_baseline(registry_of_stand_ins):
    registry, register = registry_of_stand_ins
    if registry.latest("sketchnet") is None:
        register("sketchnet", 71.97, 75.16)
    shown = format_model_versions(registry, "sketchnet")
    assert "warning: sketchnet v1 is worse than its baseline" in shown
    assert "worse than baseline" in format_models_table(registry)
