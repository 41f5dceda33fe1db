"""`farm reconstruct` as a user runs it (the shipped default models), the drawing window both depth networks share,
and bad input: one line, exit status 2, nothing written."""
from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

import species
from farm.cli import main
from gltf_validator import assert_valid_glb
from renderers import ViewRenderer
from reconstruct import InputImageError, from_params
from reconstruct.from_sketch import SketchError
from reconstruct.networks import sketch_maps
from species.meshing.gltf import read_glb_json
from test_cloud_skeleton import TREE1
from trainers.preprocess import prepare


@pytest.fixture(scope="module")
def drawings(tmp_path_factory):
    """A maple the networks never saw (seed 11), drawn as the shipped models' inputs, saved as PNG files."""
    folder = tmp_path_factory.mktemp("drawings")
    params = species.sample("maple", np.random.default_rng(11))
    skeleton, mesh = species.rebuild(params)
    renderer = ViewRenderer(256)
    try:
        tsn = renderer.render(mesh, skeleton, "tsn4", ["sketch_tsn"], np.random.default_rng(0))[0]
        front, side = renderer.render(mesh, skeleton, "two-view:shared",
                                      ["sketch_edges", "trunk_strokes", "sketch_strokes"], np.random.default_rng(0))
    finally:
        renderer.close()
    files = {"tsn": tsn.images["sketch_tsn"], "edges": front.images["sketch_edges"],
             "strokes": front.images["trunk_strokes"], "front": front.images["sketch_strokes"],
             "side": side.images["sketch_strokes"]}
    paths = {}
    for name, image in files.items():
        paths[name] = folder / f"{name}.png"
        Image.fromarray(image).save(paths[name])
    return paths


class _InkNet:
    """A stand-in depth network that returns its own preprocessed input's ink (trunk: 1 - ink, as trunk depth is 1
    where there is no stroke), to check where each network's output lands on the page."""

    input_size = 64

    def __init__(self, kind: str, channels: int, invert: bool):
        self.input_kind, self.channels, self.invert = kind, channels, invert

    def predict_view(self, image, seed: int = 0):
        prepared = prepare(image, self.input_kind, self.input_size)
        ink = prepared.image.max(axis=0, keepdims=True)
        return np.repeat(1.0 - ink if self.invert else ink, self.channels, axis=0), prepared


def test_both_networks_outputs_land_in_the_sketch_window():
    page = np.full((300, 400, 3), 255, np.uint8)
    cv2.ellipse(page, (200, 120), (120, 90), 0, 0, 360, (0, 0, 0), 2)  # the crown outline: a wide window
    strokes = np.full_like(page, 255)
    cv2.line(strokes, (200, 280), (200, 100), (255, 0, 0), 6)  # a trunk well inside it: a narrow crop of its own
    cv2.line(strokes, (200, 170), (260, 90), (0, 160, 0), 6)
    found = sketch_maps(page, strokes, silhouette_net=_InkNet("sketch", 3, False),
                        trunk_net=_InkNet("strokes", 1, True))
    assert found.silhouette.shape == (64, 64, 3) and found.trunk_depth.shape == (64, 64)
    network_strokes = found.trunk_depth < 0.5            # through the trunk network's own crop, moved here
    cut_strokes = found.strokes.min(axis=2) < 128        # the strokes image cut straight to the sketch window
    iou = (network_strokes & cut_strokes).sum() / (network_strokes | cut_strokes).sum()
    assert iou > 0.7
    assert found.camera.width == found.camera.height == 64
    with pytest.raises(InputImageError, match="one page"):
        sketch_maps(page, strokes[:200], silhouette_net=_InkNet("sketch", 3, False),
                    trunk_net=_InkNet("strokes", 1, True))


def _one_line_error(capsys, argv, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


def test_params_method_writes_a_valid_glb_and_a_dictionary_farm_tree_rebuilds(drawings, tmp_path, capsys):
    out, dictionary, report = tmp_path / "tree.glb", tmp_path / "tree.json", tmp_path / "report.png"
    assert main(["reconstruct", str(drawings["tsn"]), "--out", str(out), "--params-out", str(dictionary),
                 "--report", str(report)]) == 0
    line = capsys.readouterr().out
    assert_valid_glb(out.read_bytes(), tmp_path)
    params = json.loads(dictionary.read_text())
    assert params["species"] in [p.name for p in species.list_presets()]
    read = re.search(r"^params: species (\S+) \(confidence ([0-9.]+)\), ", line)  # which species it read, how sure
    assert read and read.group(1) == params["species"] and 0 < float(read.group(2)) <= 1, line
    assert main(["tree", "--params", str(dictionary), "--out", str(tmp_path / "again")]) == 0
    assert (tmp_path / "again" / "tree.glb").read_bytes() == out.read_bytes()
    width, height = Image.open(report).size
    assert width > 4 * height


def test_params_with_a_height_grows_that_tall_and_its_dictionary_rebuilds_the_same_tree(drawings, tmp_path, capsys):
    image = np.asarray(Image.open(drawings["tsn"]))
    guessed = from_params(image)
    for height in (0.5 * guessed.skeleton.height, 2.0 * guessed.skeleton.height):
        result = from_params(image, height=height)
        assert abs(result.skeleton.height - height) <= 0.02 * height
        assert result.params["species"] == guessed.params["species"]
        assert {k: v for k, v in result.params.items() if k != "scale"} == {
            k: v for k, v in guessed.params.items() if k != "scale"}  # only the scale changes
    out, dictionary = tmp_path / "tall.glb", tmp_path / "tall.json"
    assert main(["reconstruct", str(drawings["tsn"]), "--height", "7.5", "--out", str(out), "--params-out",
                 str(dictionary)]) == 0
    printed = re.search(r"height ([0-9.]+) m", capsys.readouterr().out)
    assert printed and abs(float(printed.group(1)) - 7.5) <= 0.02 * 7.5
    assert main(["tree", "--params", str(dictionary), "--out", str(tmp_path / "again")]) == 0
    assert (tmp_path / "again" / "tall.glb").read_bytes() == out.read_bytes()
    with pytest.raises(SketchError, match="height -1"):
        from_params(image, height=-1)


def test_sketch_depth_and_two_view_methods_write_valid_glbs(drawings, tmp_path, capsys):
    deep = tmp_path / "deep.glb"
    assert main(["reconstruct", str(drawings["edges"]), "--strokes", str(drawings["strokes"]), "--height", "9",
                 "--out", str(deep)]) == 0
    assert "sketch-depth:" in capsys.readouterr().out
    assert_valid_glb(deep.read_bytes(), tmp_path, "deep.glb")
    pair = tmp_path / "pair.glb"
    assert main(["reconstruct", "--front", str(drawings["front"]), "--side", str(drawings["side"]),
                 "--out", str(pair)]) == 0
    assert "two-view:" in capsys.readouterr().out
    assert_valid_glb(pair.read_bytes(), tmp_path, "pair.glb")


def _as_kind(grey: np.ndarray, kind: str, path: Path) -> Path:
    """The grey drawing saved as another kind of image file: the same drawing on the page."""
    if kind == "rgba":  # black ink whose alpha is its darkness, on a transparent background
        Image.fromarray(np.dstack([np.zeros(grey.shape + (3,), np.uint8), 255 - grey]), "RGBA").save(path)
    elif kind == "palette":
        Image.fromarray(grey).convert("P").save(path)
    elif kind == "deep":
        Image.fromarray(grey.astype(np.uint16) * 257).save(path)
    else:
        Image.fromarray(grey).save(path, quality=95)
    return path


def test_every_kind_of_image_file_reconstructs_as_the_drawing_it_shows(drawings, tmp_path, capsys):
    """RGBA on a transparent background, a palette PNG and a 16-bit PNG of a drawing grow the tree its 8-bit grey
    PNG grows, byte for byte; a JPEG of it grows a valid tree. Two-view reads RGBA drawings too."""
    grey = np.asarray(Image.open(drawings["tsn"]))
    assert main(["reconstruct", str(drawings["tsn"]), "--out", str(tmp_path / "grey" / "tree.glb")]) == 0
    for kind, suffix in (("rgba", "png"), ("palette", "png"), ("deep", "png"), ("jpeg", "jpg")):
        out = tmp_path / kind / "tree.glb"  # one name: the GLB holds it
        drawing = _as_kind(grey, kind, tmp_path / f"{kind}.{suffix}")
        assert main(["reconstruct", str(drawing), "--out", str(out), "--report", str(tmp_path / f"{kind}.png")]) == 0
        if kind == "jpeg":
            assert_valid_glb(out.read_bytes(), tmp_path, "jpeg.glb")
        else:
            assert out.read_bytes() == (tmp_path / "grey" / "tree.glb").read_bytes(), kind
    pair = {view: _as_kind(np.asarray(Image.open(drawings[view])), "rgba", tmp_path / f"{view}_rgba.png")
            for view in ("front", "side")}
    assert main(["reconstruct", "--front", str(pair["front"]), "--side", str(pair["side"]),
                 "--out", str(tmp_path / "pair.glb")]) == 0
    assert "two-view:" in capsys.readouterr().out


def test_the_api_returns_skeleton_mesh_and_report(drawings):
    image = np.asarray(Image.open(drawings["tsn"]))
    result = from_params(image, seed=3, fit_evals=0)
    assert result.params["seed"] == 3 and result.skeleton.n_nodes > 10 and result.mesh.n_faces > 0
    assert set(result.timings) == {"network", "grow_mesh", "total"} and result.maps["input"].shape == (224, 224)
    name, confidence = result.maps["species"]
    assert name == result.params["species"] and 0.0 < confidence <= 1.0
    # Fitted (the default), the split decisions may come from one of the next decode seeds.
    fitted = from_params(image, seed=3, fit_evals=6)
    assert fitted.params["seed"] in (3, 4, 5) and list(fitted.timings) == ["network", "fit", "grow_mesh", "total"]
    assert fitted.maps["fit"].score >= fitted.maps["fit"].first_score
    with pytest.raises(InputImageError, match=r"\(10, 10, 2\)"):
        from_params(np.zeros((10, 10, 2), np.uint8))


@pytest.mark.skipif(not TREE1.is_file(), reason="shared/data/pointclouds/tree1.xyz is missing")
def test_cloud_summary_is_one_short_line_and_the_timings_go_to_verbose_not_the_glb(tmp_path, capsys):
    out = tmp_path / "tree1.glb"
    assert main(["reconstruct", str(TREE1), "--out", str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == 1 and len(printed[0]) - len(str(out)) <= 100, printed
    assert "skeleton" not in printed[0]
    first = out.read_bytes()
    root = next(node for node in read_glb_json(first)["nodes"] if "extras" in node)
    assert "timings_s" not in root["extras"]["treefarm"]  # seconds differ run to run; the file must not
    assert main(["reconstruct", str(TREE1), "--out", str(out), "--verbose"]) == 0
    stages = capsys.readouterr().out.splitlines()[:-1]
    assert {"read", "mesh"} <= {line.split()[0] for line in stages} and out.read_bytes() == first


def test_bad_input_is_one_line_and_writes_nothing(drawings, tmp_path, capsys):
    out = tmp_path / "t.glb"
    text = tmp_path / "notes.png"
    text.write_text("not a picture")
    _one_line_error(capsys, ["reconstruct", str(text), "--out", str(out)], "is not an image file")
    floats = tmp_path / "floats.tif"
    Image.fromarray(np.full((64, 64), 0.5, np.float32)).save(floats)
    _one_line_error(capsys, ["reconstruct", str(floats), "--out", str(out)], "floating-point pixels")
    blank = tmp_path / "blank.png"
    Image.fromarray(np.full((64, 64), 255, np.uint8)).save(blank)
    _one_line_error(capsys, ["reconstruct", str(blank), "--out", str(out)], "blank")
    black = tmp_path / "black.png"
    Image.fromarray(np.zeros((64, 64), np.uint8)).save(black)
    _one_line_error(capsys, ["reconstruct", str(black), "--out", str(out)], "blank")
    tiny = tmp_path / "tiny.png"
    Image.fromarray(np.array([[0, 255], [255, 0]], np.uint8)).save(tiny)
    _one_line_error(capsys, ["reconstruct", str(tiny), "--out", str(out)])
    _one_line_error(capsys, ["reconstruct", str(drawings["tsn"]), "--fit-evals", "-1", "--out", str(out)],
                    "--fit-evals -1 is invalid")
    cloud = tmp_path / "scan.xyz"
    np.savetxt(cloud, np.random.default_rng(0).random((50, 3)))
    _one_line_error(capsys, ["reconstruct", str(cloud), "--fit-evals", "4", "--out", str(out)], "--fit-evals")
    white = tmp_path / "white.png"
    Image.fromarray(np.full((256, 256, 3), 255, np.uint8)).save(white)
    _one_line_error(capsys, ["reconstruct", str(drawings["edges"]), "--strokes", str(white), "--out", str(out)])
    broken = tmp_path / "broken.png"
    lines = np.full((128, 128), 255, np.uint8)
    cv2.line(lines, (64, 120), (64, 60), 0, 1)
    cv2.line(lines, (20, 40), (40, 10), 0, 1)
    Image.fromarray(lines).save(broken)
    _one_line_error(capsys, ["reconstruct", "--front", str(broken), "--side", str(broken), "--out", str(out)],
                    "pieces")
    _one_line_error(capsys, ["reconstruct", str(drawings["tsn"]), "--models", str(tmp_path / "nowhere"),
                             "--out", str(out)], "no model registry")
    assert not (tmp_path / "nowhere").exists()
    _one_line_error(capsys, ["reconstruct", str(drawings["tsn"]), "--method", "cloud", "--out", str(out)],
                    "is not a point cloud")
    _one_line_error(capsys, ["reconstruct", str(drawings["edges"]), "--method", "sketch-depth", "--out", str(out)],
                    "--strokes")
    _one_line_error(capsys, ["reconstruct", str(drawings["tsn"]), "--out", str(tmp_path / "t.png")], ".glb or .obj")
    assert not out.exists()
