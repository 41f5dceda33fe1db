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
    header = table.splitlines()[0].split()
    assert header[2:4] == ["height_m", "crown_radius_m"] and "3_palm_3" in table  # the crown column is a radius


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


def test_a_preset_as_json_reads_as_a_sapling_preset_and_stored_draws_beside_its_ranges_are_ignored(tmp_path, capsys):
    import ast

    settings = ast.literal_eval((PRESETS / "white_birch.py").read_text())
    (tmp_path / "birch.json").write_text(json.dumps(settings))
    assert main(["tree", "--params", str(tmp_path / "birch.json"), "--out", str(tmp_path / "out")]) == 0
    (tmp_path / "mixed").mkdir()  # the same name: the file's name is in the GLB
    (tmp_path / "mixed" / "birch.json").write_text(json.dumps({**settings, "curveV1": [0, 1, 0, 0]}))
    assert main(["tree", "--params", str(tmp_path / "mixed" / "birch.json"), "--out", str(tmp_path / "out2")]) == 0
    assert (tmp_path / "out2" / "birch.glb").read_bytes() == (tmp_path / "out" / "birch.glb").read_bytes()


def _aspen_with(tmp_path: Path, name: str, extra: dict) -> Path:
    import ast

    settings = {**ast.literal_eval((PRESETS / "quaking_aspen.py").read_text()), **extra}
    path = tmp_path / name
    path.write_text(json.dumps(settings) if name.endswith(".json") else repr(settings))
    return path


STORED = {"curveV1": [1.0, 2.0, 0.0, 0.0], "curveV2": [0.5, 1.0, 0.0, 0.0]}


def test_old_and_result_presets_grow_as_the_add_on_loads_them_and_verbose_names_what_is_ignored(tmp_path, capsys):
    files = [_aspen_with(tmp_path, "old_key.py", {"startCurv": 0.0}),
             _aspen_with(tmp_path, "old_wind.py", {"windSpeed": 2.0, "windGust": 0.0}),
             _aspen_with(tmp_path, "stored.py", STORED), _aspen_with(tmp_path, "stored_json.json", STORED),
             _aspen_with(tmp_path, "realized.json", {**STORED, "draws": "realized"})]
    assert main(["tree", "--params", str(PRESETS / "quaking_aspen.py"), *map(str, files), "--out",
                 str(tmp_path / "out"), "--verbose"]) == 0
    out = capsys.readouterr().out
    assert "  ignored startCurv: a property Sapling 0.3.4 no longer defines" in out
    assert "  ignored windSpeed: " in out and "  ignored windGust: " in out
    assert out.count("  ignored curveV1: a stored draw (TreeSketchNet's), which the add-on does not know: grown "
                     "from Sapling's ranges") == 2
    assert f"{files[4]}: Weber-Penn, draws: realized" in out and "  ignored curveV: the range" in out
    # the same tree as the add-on's preset: the same vertices (the file's name is in the GLB, so not its bytes)
    vertices = {path.stem: trimesh.load(path, force="mesh").vertices for path in (tmp_path / "out").iterdir()}
    for name in ("old_key", "old_wind", "stored", "stored_json"):
        assert (vertices[name] == vertices["quaking_aspen"]).all(), name
    assert vertices["realized"].shape != vertices["quaking_aspen"].shape  # grown from the stored draws


def test_a_known_key_with_a_bad_value_in_an_old_preset_is_one_line(tmp_path, capsys):
    bad = _aspen_with(tmp_path, "bad.py", {"startCurv": 0.0, "levels": "three"})
    assert main(["tree", "--params", str(bad), "--out", str(tmp_path / "out")]) == 2
    line = capsys.readouterr().err.strip()
    assert len(line.splitlines()) == 1 and "bad.py" in line and "'levels' = 'three'" in line
    assert not (tmp_path / "out").exists()
