"""Bad inputs to `farm library` (issue 20): one line, exit status 2, nothing written; and `--species` selects
the species of a build instead of being ignored."""
from __future__ import annotations

import json

import pytest

import farm.library.job as library_job
from farm.cli import main as farm_main
from farm.library.spec import LibrarySpecError, parse_library_spec


@pytest.fixture
def captured_specs(monkeypatch):
    """The specs `farm library` would build, without building them."""
    specs = []

    def fake_run_library(spec, out, **_):
        specs.append(spec)
        return {"manifest": {"counts": {"failed": 0}}, "catalog": {"assets": 0, "blender": 0}}

    monkeypatch.setattr(library_job, "run_library", fake_run_library)
    return specs


def test_species_selects_the_species_of_the_build(tmp_path, captured_specs):
    out = tmp_path / "out"
    assert farm_main(["library", "--species", "palm", "--per-species", "2", "--out", str(out), "--quiet"]) == 0
    assert captured_specs[0].species_counts == {"palm": 2}
    assert farm_main(["library", "--species", "palm,maple", "--out", str(out), "--quiet"]) == 0
    assert captured_specs[1].species_counts == {"palm": 4, "maple": 4}


@pytest.mark.parametrize("argv", [["--species", "no_such_tree"], ["--species", "palm", "--seed", "3"]])
def test_misread_build_flags_are_refused_before_anything_is_written(tmp_path, capsys, captured_specs, argv):
    out = tmp_path / "out"
    assert farm_main(["library", *argv, "--out", str(out), "--quiet"]) == 2
    assert not captured_specs and not out.exists()
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.parametrize("formats", [["fbx"], ["blend"], ["usd", "fbx", "blend"]])
def test_blender_formats_without_glb_are_refused(formats):
    with pytest.raises(LibrarySpecError, match="together with 'glb'"):
        parse_library_spec({"formats": formats})
    parse_library_spec({"formats": [*formats, "glb"]})


def test_a_refused_library_into_a_farm_dataset_writes_nothing(tmp_path, capsys):
    dataset = tmp_path / "dataset"
    dataset.mkdir()
    (dataset / "_job.json").write_text(json.dumps({"spec_digest": "0" * 64}))
    before = sorted(p.name for p in dataset.iterdir())
    assert farm_main(["library", "--species", "palm", "--per-species", "1", "--out", str(dataset), "--quiet"]) == 2
    assert sorted(p.name for p in dataset.iterdir()) == before
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
