"""The MLflow model registry wrapper: versions and aliases, files back byte for byte, all-or-nothing registration,
one-line errors for bad registries and unknown names, and a store that a fresh process reads back."""
from __future__ import annotations

import hashlib
import json
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from trainers.model_tables import format_model_versions, format_models_table
from trainers.registry import ARTIFACT_FOLDER, CHAMPION, DATABASE_FILE, LATEST, ModelVersion, RegistryError, open_registry

ROOT = Path(__file__).resolve().parents[2]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def model_files(tmp_path_factory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("files")
    contents = [bytes(range(256)) * 40, np.random.default_rng(22).bytes(3000)]
    files = {"weights.pt": folder / "w.bin", "model.onnx": folder / "net.onnx"}  # logged under other names
    for data, path in zip(contents, files.values()):
        path.write_bytes(data)
    return files


@pytest.fixture(scope="module")
def registry(tmp_path_factory):
    """One registry folder for the module (creating a SQLite store takes seconds); tests use their own models."""
    return open_registry(tmp_path_factory.mktemp("reg") / "registry")


def _register(registry, name, files, score=80.0, **extra):
    return registry.register(name, files, metrics={"score": score, "score_baseline": 60.0, "species_acc": 0.9},
                             params={"epochs": 3, "width": "b0"}, tags={"code_version": "abc123"},
                             json_blobs={"split": {"train": [1, 2], "test": [3]}, "codec": {"version": 1}}, **extra)


@pytest.fixture(scope="module")
def two_versions(registry, model_files):
    """Model 'sketchnet': version 1 (champion) and version 2 (latest)."""
    first = _register(registry, "sketchnet", model_files, score=80.0)
    second = _register(registry, "sketchnet", model_files, score=85.0)
    registry.promote("sketchnet", first.version)
    return first, second


def _runs(registry, name):
    from mlflow.entities import ViewType

    experiment = registry.client.get_experiment_by_name(name)
    return [] if experiment is None else registry.client.search_runs([experiment.experiment_id],
                                                                     run_view_type=ViewType.ALL)


# ------------------------------------------------------------------------------------------------ versions
def test_register_numbers_versions_and_the_newest_is_latest(registry, two_versions):
    first, second = two_versions
    assert (first.version, second.version) == (1, 2)
    assert isinstance(second, ModelVersion) and second.name == "sketchnet"
    assert registry.latest("sketchnet").version == 2
    assert LATEST in registry.version("sketchnet", 2).aliases
    assert LATEST not in registry.version("sketchnet", 1).aliases
    assert [v.version for v in registry.versions("sketchnet")] == [1, 2]
    assert "sketchnet" in registry.names()


def test_a_version_carries_its_metrics_params_tags_and_source(registry, two_versions):
    version = registry.version("sketchnet", "2")
    assert version.metrics == {"score": 85.0, "score_baseline": 60.0, "species_acc": 0.9}
    assert version.params == {"epochs": "3", "width": "b0"}
    assert version.tags == {"code_version": "abc123"}  # MLflow's own mlflow.* tags are left out
    assert version.source.endswith(f"/{ARTIFACT_FOLDER}") and version.run_id in version.source
    assert version.created.tzinfo is not None


def test_promote_moves_the_champion_and_leaves_latest_alone(registry, model_files):
    _register(registry, "promoted", model_files)
    _register(registry, "promoted", model_files)
    assert registry.champion("promoted") is None
    assert registry.promote("promoted", 1).aliases == (CHAMPION,)
    assert registry.champion("promoted").version == 1
    registry.promote("promoted", LATEST)
    assert registry.champion("promoted").version == 2
    assert registry.version("promoted", CHAMPION).aliases == (CHAMPION, LATEST)
    assert registry.version("promoted", 1).aliases == ()


def test_champion_and_latest_of_a_model_not_registered_are_none(registry):
    assert registry.champion("never-trained") is None and registry.latest("never-trained") is None


# ------------------------------------------------------------------------------------------------ files back
def test_download_gives_back_the_files_byte_for_byte(registry, two_versions, model_files, tmp_path):
    folder = registry.download("sketchnet", CHAMPION, tmp_path / "champion")
    assert folder == tmp_path / "champion"
    assert sorted(p.name for p in folder.iterdir()) == ["codec.json", "model.onnx", "split.json", "weights.pt"]
    for name, original in model_files.items():
        assert _sha256(folder / name) == _sha256(original)
    assert json.loads((folder / "split.json").read_text()) == {"train": [1, 2], "test": [3]}


def test_download_without_a_destination_makes_a_folder(registry, two_versions, model_files):
    folder = registry.download("sketchnet", 2)
    try:
        assert _sha256(folder / "weights.pt") == _sha256(model_files["weights.pt"])
    finally:
        shutil.rmtree(folder)


def test_download_refuses_a_folder_that_holds_files(registry, two_versions, tmp_path):
    (tmp_path / "keep.txt").write_text("mine")
    with pytest.raises(RegistryError, match="not an empty folder"):
        registry.download("sketchnet", 1, tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["keep.txt"]


def test_load_json_reads_a_blob_and_names_the_known_ones(registry, two_versions):
    assert registry.load_json("sketchnet", CHAMPION, "codec") == {"version": 1}
    with pytest.raises(RegistryError, match=r"no JSON blob 'report'; it has codec, split"):
        registry.load_json("sketchnet", 1, "report")


# ------------------------------------------------------------------------------------------------ tables
def test_models_table_names_each_model_with_latest_champion_and_baselines(registry, two_versions):
    table = format_models_table(registry)
    row = next(line for line in table.splitlines() if line.startswith("sketchnet "))
    assert row.split()[1:4] == ["2", "v2", "v1"]  # versions, latest, champion
    assert "score 80 (60)" in row  # the champion's metric with its baseline in brackets


def test_model_versions_lists_newest_first_and_marks_the_champion(registry, two_versions):
    text = format_model_versions(registry, "sketchnet")
    lines = text.splitlines()
    version_rows = [line.split() for line in lines if line.strip().startswith("v") and "20" in line]
    assert [(row[0], row[1]) for row in version_rows] == [("v2", LATEST), ("v1", CHAMPION)]
    header = next(line for line in lines if line.startswith("metric"))
    assert header.split()[-3:] == ["v2", "v1", CHAMPION]
    score = next(line for line in lines if line.startswith("score "))
    assert score.split() == ["score", "85", "(60)", "80", "(60)"]
    assert not any(line.startswith("score_baseline") for line in lines)


def test_an_empty_registry_says_so(tmp_path):
    assert "no models" in format_models_table(open_registry(tmp_path / "empty"))


# ------------------------------------------------------------------------------------------------ all or nothing
def _fail_in_version_creation(registry, monkeypatch, after_store_made_it: bool):
    from mlflow.exceptions import MlflowException

    real = registry.client.create_model_version

    def broken(*args, **kwargs):
        if after_store_made_it:
            real(*args, **kwargs)  # e.g. the server made it, then the connection dropped
        raise MlflowException("simulated failure")

    monkeypatch.setattr(registry.client, "create_model_version", broken)


@pytest.mark.parametrize("after_store_made_it", [False, True])
def test_a_failed_registration_leaves_versions_and_champion_as_they_were(registry, model_files, monkeypatch,
                                                                          after_store_made_it):
    name = f"atomic-{int(after_store_made_it)}"
    _register(registry, name, model_files)
    registry.promote(name, 1)
    _fail_in_version_creation(registry, monkeypatch, after_store_made_it)
    with pytest.raises(RegistryError, match=f"cannot register model '{name}'.*simulated failure"):
        _register(registry, name, model_files, score=99.0)
    monkeypatch.undo()
    assert [v.version for v in registry.versions(name)] == [1]
    assert registry.champion(name).version == 1 and registry.latest(name).version == 1
    failed = [run for run in _runs(registry, name) if run.info.status == "FAILED"]
    assert len(failed) == 1 and failed[0].info.lifecycle_stage == "deleted"


def test_a_failed_first_registration_leaves_no_model(registry, model_files, monkeypatch):
    _fail_in_version_creation(registry, monkeypatch, after_store_made_it=True)
    with pytest.raises(RegistryError):
        _register(registry, "first-fails", model_files)
    monkeypatch.undo()
    assert "first-fails" not in registry.names()


def test_a_missing_file_is_named_and_starts_no_run(registry, model_files, tmp_path):
    files = dict(model_files, **{"extra.bin": tmp_path / "absent.bin"})
    with pytest.raises(RegistryError, match=r"file 'extra.bin' = '.*absent.bin' does not exist"):
        _register(registry, "missing-file", files)
    assert _runs(registry, "missing-file") == [] and "missing-file" not in registry.names()


@pytest.mark.parametrize("kwargs, message", [
    ({"metrics": {"score": float("nan")}}, r"metric 'score' = nan is invalid"),
    ({"metrics": {"score": "high"}}, r"metric 'score' = 'high' is invalid"),
    ({"tags": {"mlflow.user": "x"}}, r"tag name 'mlflow.user' is invalid"),
    ({"json_blobs": {"weights.pt": {}}, "files_named": "weights.pt.json"}, r"same name"),
    ({"json_blobs": {"split": {1, 2}}}, r"JSON blob 'split' cannot be written as JSON"),
    ({"name": "no spaces please"}, r"model name 'no spaces please' is invalid"),
    ({"files": {}}, r"at least one file"),
])
def test_bad_registration_input_is_rejected_by_name(registry, model_files, kwargs, message):
    kwargs = dict(kwargs)
    files = kwargs.pop("files", {kwargs.pop("files_named", "weights.pt"): model_files["weights.pt"]})
    with pytest.raises(RegistryError, match=message):
        registry.register(kwargs.pop("name", "bad-input"), files, **kwargs)
    assert "bad-input" not in registry.names()


# ------------------------------------------------------------------------------------------------ bad registries
def _closed_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def _one_line_error(models) -> str:
    with pytest.raises(RegistryError) as caught:
        open_registry(models)
    message = str(caught.value)
    assert "\n" not in message and str(models) in message
    return message


def test_an_unreachable_server_is_one_line_naming_it():
    _one_line_error(f"http://127.0.0.1:{_closed_port()}")


def test_an_unsupported_uri_is_one_line_naming_it():
    assert "unsupported URI" in _one_line_error("bogus://somewhere")


def test_a_folder_that_cannot_be_made_is_one_line_naming_it(tmp_path):
    (tmp_path / "a-file").write_text("")
    assert "Not a directory" in _one_line_error(tmp_path / "a-file" / "registry")
    assert "is a file, not a folder" in _one_line_error(tmp_path / "a-file")


def test_a_folder_holding_a_corrupt_database_is_one_line_naming_it(tmp_path):
    (tmp_path / DATABASE_FILE).write_text("not a database")
    assert "file is not a database" in _one_line_error(tmp_path)


@pytest.mark.parametrize("call, message", [
    (lambda r: r.versions("no-such-model"), r"has no model 'no-such-model'; it has .*sketchnet"),
    (lambda r: r.version("sketchnet", 7), r"no version 7; it has versions 1, 2 and aliases champion \(v1\), "
                                          r"latest \(v2\)"),
    (lambda r: r.download("sketchnet", "gold"), r"no alias 'gold'; it has versions 1, 2"),
    (lambda r: r.promote("no-such-model", 1), r"has no model 'no-such-model'"),
])
def test_an_unknown_model_version_or_alias_is_one_line_listing_what_exists(registry, two_versions, call, message):
    with pytest.raises(RegistryError, match=message) as caught:
        call(registry)
    assert "\n" not in str(caught.value)


# ------------------------------------------------------------------------------------------------ another process
def test_a_fresh_process_reads_the_versions_back_and_prints_nothing_of_mlflow(registry, two_versions, tmp_path):
    script = ("import sys\nfrom trainers.registry import open_registry\n"
              "open_registry(sys.argv[2])\n"  # a new store: MLflow's table creation must stay quiet
              "r = open_registry(sys.argv[1])\n"
              "print(r.champion('sketchnet').version, r.latest('sketchnet').version, r.version('sketchnet', 1).run_id)")
    done = subprocess.run([sys.executable, "-c", script, registry.label, str(tmp_path / "new-registry")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["1", "2", two_versions[0].run_id]
    assert done.stderr == ""
    assert (tmp_path / "new-registry" / DATABASE_FILE).is_file()
