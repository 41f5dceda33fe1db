"""`farm tree` and `farm species` as a user runs them: files written, tables printed, one-line errors."""
import json
from pathlib import Path

import trimesh

from farm.cli import main

SAPLING = Path(__file__).resolve().parents[3] / "shared" / "data" / "sapling"


def test_tree_from_a_species_writes_a_glb(tmp_path, capsys):
    out = tmp_path / "maple.glb"
    assert main(["tree", "--species", "maple", "--seed", "2", "--out", str(out), "--save-params"]) == 0
    scene = trimesh.load(out)
    assert len(scene.geometry) == 2
    assert json.loads(out.with_suffix(".json").read_text())["species"] == "maple"
    assert "maple" in capsys.readouterr().out


def test_tree_from_dictionaries_writes_one_file_per_dictionary(tmp_path, capsys):
    files = [str(SAPLING / "0_acer_2.json"), str(SAPLING / "3_palm_3.json")]
    assert main(["tree", "--params", *files, "--out", str(tmp_path / "trees")]) == 0
    assert sorted(p.name for p in (tmp_path / "trees").iterdir()) == ["0_acer_2.glb", "3_palm_3.glb"]
    table = capsys.readouterr().out
    assert "height_m" in table and "3_palm_3" in table


def test_tree_as_obj_writes_obj_mtl_and_textures(tmp_path):
    assert main(["tree", "--params", str(SAPLING / "6_pine.json"), "--out", str(tmp_path), "--format", "obj"]) == 0
    names = {p.suffix for p in tmp_path.iterdir()}
    assert {".obj", ".mtl", ".png"} <= names
    mesh = trimesh.load(tmp_path / "6_pine.obj", force="mesh")
    assert len(mesh.faces) > 1000


def test_bad_dictionary_prints_one_line_and_writes_nothing(tmp_path, capsys):
    good = SAPLING / "0_acer_2.json"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({**json.loads(good.read_text()), "levels": 9}))
    out = tmp_path / "out"
    assert main(["tree", "--params", str(good), str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "'levels' = 9" in err and "[1, 4]" in err and "Traceback" not in err
    assert str(bad) in err
    assert not out.exists() or not any(out.iterdir())


def test_bad_json_and_unknown_species_are_one_line_errors(tmp_path, capsys):
    broken = tmp_path / "broken.json"
    broken.write_text("{not json")
    assert main(["tree", "--params", str(broken), "--out", str(tmp_path / "o")]) == 2
    assert "not valid JSON" in capsys.readouterr().err
    assert main(["tree", "--species", "baobab", "--out", str(tmp_path / "x.glb")]) == 2
    assert "unknown species 'baobab'" in capsys.readouterr().err
    assert not (tmp_path / "x.glb").exists()


def test_species_lists_every_preset_with_its_generator(capsys):
    assert main(["species"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["name", "generator", "description"]
    assert sum("weber_penn" in line for line in lines) >= 12


PRESETS = SAPLING.parents[1] / "tools" / "sapling" / "add_curve_sapling" / "presets"


def test_tree_from_a_sapling_preset_file_says_how_it_reads_with_verbose(tmp_path, capsys):
    preset = PRESETS / "acer.py"
    assert main(["tree", "--params", str(preset), str(SAPLING / "6_pine.json"), "--out", str(tmp_path),
                 "--verbose"]) == 0
    out = capsys.readouterr().out
    assert f"{preset}: Weber-Penn, draws: ranges" in out and "ignored af1:" in out
    assert "clamped baseSize_s: 4.0 -> 1.0" in out and "6_pine.json: Weber-Penn, draws: realized" in out
    assert len(trimesh.load(tmp_path / "acer.glb").geometry) == 2


def test_a_preset_as_json_reads_as_a_sapling_preset_and_a_mixed_one_is_refused(tmp_path, capsys):
    import ast

    settings = ast.literal_eval((PRESETS / "white_birch.py").read_text())
    (tmp_path / "birch.json").write_text(json.dumps(settings))
    assert main(["tree", "--params", str(tmp_path / "birch.json"), "--out", str(tmp_path / "out")]) == 0
    (tmp_path / "mixed.json").write_text(json.dumps({**settings, "curveV1": [0, 1, 0, 0]}))
    assert main(["tree", "--params", str(tmp_path / "mixed.json"), "--out", str(tmp_path / "out2")]) == 2
    line = capsys.readouterr().err.strip()
    assert "mixed.json" in line and "curveV1" in line and len(line.splitlines()) == 1
    assert not (tmp_path / "out2").exists()
