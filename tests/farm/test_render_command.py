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
