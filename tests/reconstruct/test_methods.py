"""The reconstruction registry reaches every place that lists methods. A throwaway method registered in
`reconstruct.methods.METHODS` (a stick as tall as asked, read from a rendered mask) is a choice of `farm reconstruct`
and runs there, is planned and evaluated by `farm evaluate` (one unit in this process: a Ray worker would not see
the patch), and is in benchmarks.bench_reconstruct's methods; docs/reconstruct.md's table is the registry's."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from benchmarks import bench_reconstruct
from farm.cli import main
from farm.evaluate.job import EvaluationError, evaluation_data_spec, evaluate_unit, plan_evaluation
from farm.evaluate.methods import METHODS as EVALUATED, EvalSettings, Needs, needs_of
from farm.jobs import parse_spec
from farm.pipeline import run_job
from reconstruct import Reconstruction
from reconstruct.methods import METHODS, Input, Method, MethodError, Rendered, get_method, methods_table
from species import Skeleton, build_mesh

ROOT = Path(__file__).resolve().parents[2]
STICK = "stick"


def _stick(inputs, options) -> Reconstruction:
    """A three-node trunk as tall as asked (4 m when not), whatever the drawing says."""
    height = options.height or 4.0
    positions = np.array([[0, 0, 0], [0, 0, height / 2], [0, 0, height]], np.float32)
    skeleton = Skeleton(positions, np.array([-1, 0, 1], np.int32), np.array([0.1, 0.06, 0.02], np.float32),
                        np.zeros(3, np.uint8))
    return Reconstruction(STICK, skeleton, build_mesh(skeleton, {"name": STICK}), timings={"grow": 0.0, "total": 0.0},
                          maps={"outline": inputs["outline"]})


@pytest.fixture
def stick(monkeypatch) -> Method:
    method = Method(STICK, (Input("outline", "image", "the tree's mask", rendered=Rendered("tsn4", "front", "mask")),),
                    _stick, summary="a stick as tall as asked", source="this test")
    monkeypatch.setitem(METHODS, STICK, method)
    return method


@pytest.fixture(scope="module")
def one_tree(tmp_path_factory, ray_session):
    """A dataset of one small tree whose tsn4 views store the mask (what the stick reads)."""
    out = tmp_path_factory.mktemp("one-tree") / "data"
    spec = parse_spec({"name": "one-tree", "seed": 5, "trees": 1, "species": {"sc_young_sapling": 1},
                       "render": {"rig": "tsn4", "size": 64, "outputs": ["mask"]}, "store_glb": False,
                       "shard_size": 1})
    run_job(spec, str(out), progress=False)
    return out


def test_a_registered_method_is_a_choice_of_farm_reconstruct_and_runs_there(stick, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    help_text = capsys.readouterr().out
    assert "two-view,cloud,photos,stick}" in help_text and "a stick as tall as asked (this test)" in help_text
    drawing = tmp_path / "outline.png"
    Image.fromarray(np.full((32, 32), 255, np.uint8)).save(drawing)
    out, report = tmp_path / "stick.glb", tmp_path / "report.png"
    assert main(["reconstruct", str(drawing), "--method", STICK, "--height", "3", "--out", str(out),
                 "--report", str(report)]) == 0
    assert capsys.readouterr().out.startswith("stick: 3 nodes, height 3.00 m")
    assert out.read_bytes()[:4] == b"glTF" and report.read_bytes()[:4] == b"\x89PNG"
    # What it does not read is refused as for any method.
    assert main(["reconstruct", str(drawing), "--method", STICK, "--strokes", str(drawing), "--out", str(out)]) == 2
    assert "are sketch-depth options, not stick's" in capsys.readouterr().err


def test_a_registered_method_is_planned_and_evaluated(stick, one_tree, tmp_path, capsys):
    assert STICK in EVALUATED and EVALUATED[STICK].needs == needs_of(STICK) == Needs("tsn4", ("front",), ("mask",))
    assert "mask" in next(line for line in evaluation_data_spec().splitlines() if "outputs:" in line)
    with pytest.raises(SystemExit):
        main(["evaluate", "--help"])
    assert "stick" in capsys.readouterr().out
    with pytest.raises(EvaluationError, match="allowed params, .*, stick"):
        plan_evaluation([str(one_tree)], ["lidar"], part="all")
    plan = plan_evaluation([str(one_tree)], [STICK], part="all")
    assert [(u.method, u.views) for u in plan.units] == [(STICK, (("front", "front"),))]
    row = evaluate_unit(plan.units[0], str(tmp_path), None, EvalSettings(surface_samples=0))
    assert row["status"] == "ok", row["error"]
    assert row["height_rel_error"] < 0.01  # grown at the true height, as every drawing is
    assert 0 <= row["silhouette_iou_input"] <= 1 and row["seconds_grow"] == 0.0 and row["seconds_scoring"] > 0
    assert (tmp_path / row["panel"]).read_bytes()[:4] == b"\x89PNG"


def test_a_registered_drawing_method_is_benchmarked(stick, tmp_path, capsys):
    assert bench_reconstruct.drawn_methods() == ["params", "sketch-depth", "two-view", STICK]
    bench_reconstruct.main(["--methods", STICK, "--trees", "1", "--surface-samples", "0", "--sheet-trees", "0",
                            "--out", str(tmp_path), "--no-results"])
    text = capsys.readouterr().out
    assert "stick: quality on held-out trees" in text and "stick: seconds per tree and stage" in text
    assert "failed" not in text


def test_an_unknown_method_names_the_known_ones():
    assert get_method("two-view").reads[0].name == "front"
    with pytest.raises(MethodError, match="unknown method 'lidar': allowed params, sketch-depth, two-view, cloud, photos"):
        get_method("lidar")


def test_the_docs_table_of_methods_is_the_registrys():
    assert methods_table() in (ROOT / "docs" / "reconstruct.md").read_text(), \
        "docs/reconstruct.md: paste `python -m reconstruct.methods` over its methods table"
