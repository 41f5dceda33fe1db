"""`farm render`: one PNG per view and output, a cameras.json that decodes them, one-line errors."""
from __future__ import annotations

import json

import cv2
import numpy as np

from farm.cli import main


def test_render_writes_a_png_per_view_and_output_and_a_decodable_depth(tmp_path, capsys):
    out = tmp_path / "views"
    status = main(["render", "--species", "maple", "--seed", "2", "--rig", "two-view", "--size", "64",
                   "--styles", "depth,mask,sketch_tsn", "--out", str(out)])
    assert status == 0
    meta = json.loads((out / "cameras.json").read_text())
    assert [v["name"] for v in meta["views"]] == ["front", "side"]
    assert len(list(out.glob("view*.png"))) == 2 * 3 and (out / "contact_sheet.png").is_file()
    view = meta["views"][0]
    depth_png = cv2.imread(str(out / view["images"]["depth"]["file"]), cv2.IMREAD_UNCHANGED)
    assert depth_png.dtype == np.uint16 and depth_png.shape == (64, 64)
    metres = depth_png * view["images"]["depth"]["scale"]
    hit = metres > 0
    assert view["near"] - 0.01 <= metres[hit].min() and metres[hit].max() <= view["far"] + 0.01
    mask = cv2.imread(str(out / view["images"]["mask"]["file"]), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(mask > 0, hit)
    assert "ms" in capsys.readouterr().out


def test_render_rejects_an_unknown_style_in_one_line(tmp_path, capsys):
    status = main(["render", "--species", "maple", "--styles", "depth,watercolour", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert status == 2 and "watercolour" in err and "sketch_tsn" in err and len(err.strip().splitlines()) == 1


def test_render_refuses_an_out_that_is_a_file_before_growing_the_tree(tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("keep me")
    assert main(["render", "--species", "maple", "--size", "32", "--out", str(notes)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # no "tree: ... grown and meshed" line: the path was checked first
    assert captured.err.strip().splitlines() == [f"farm: error: --out {notes} is not a folder: allowed a folder, "
                                                 f"made if missing"]
    assert notes.read_text() == "keep me" and sorted(tmp_path.iterdir()) == [notes]


def test_render_refuses_an_out_under_a_file(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("keep me")
    assert main(["render", "--species", "maple", "--size", "32", "--out", str(tmp_path / "notes.txt/views")]) == 2
    assert f"({tmp_path / 'notes.txt'} is a file)" in capsys.readouterr().err


def test_render_counts_a_single_output_in_the_singular(tmp_path, capsys):
    assert main(["render", "--species", "maple", "--rig", "two-view", "--size", "32", "--styles", "depth",
                 "--out", str(tmp_path / "views")]) == 0
    out = capsys.readouterr().out
    assert "(pyrender, 1 output)" in out and f"wrote 2 views to {tmp_path / 'views'}" in out


def test_the_blender_backend_writes_a_contact_sheet_too(tmp_path, monkeypatch):
    from renderers import blender

    def photos_standin(glb, cameras, out_dir, samples=16):
        images, depths, masks = [], [], []
        for k, camera in enumerate(cameras):
            for kind, pixels, files in (("", np.full((32, 32, 3), 90, np.uint8), images),
                                        ("_depth", np.full((32, 32), 900, np.uint16), depths),
                                        ("_mask", np.ones((32, 32), np.uint8), masks)):
                files.append(out_dir / f"view_{k:03d}{kind}.png")
                cv2.imwrite(str(files[-1]), pixels)
        (out_dir / "cameras.json").write_text(json.dumps({"views": [{"name": c.name} for c in cameras]}))
        return blender.BlenderPhotos(images, depths, masks, [0.01] * len(cameras), list(cameras),
                                     out_dir / "cameras.json", [0.0] * len(cameras), 0.0)

    monkeypatch.setattr(blender, "render_photos", photos_standin)
    out = tmp_path / "photos"
    assert main(["render", "--species", "maple", "--rig", "two-view", "--size", "32", "--backend", "blender",
                 "--out", str(out)]) == 0
    assert (out / "contact_sheet.png").is_file()
