"""`farm evaluate`'s fit to the drawing: the budget (`--fit-evals`, `EvalSettings.fit_evals`) reaches the drawing
methods, with the worker's renderer; a bad budget is one line, exit 2; a report of another budget is not resumed;
and a sketch is scored as a filled outline, so a contour drawing matches the solid tree it outlines.

A held-out tree here is a lollipop (a stick under a ball, a tube whose radius follows a circle) with its views
rendered in this process: no dataset, no Ray."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

import renderers
from farm.cli import main
from farm.evaluate.inputs import drawing_fit
from farm.evaluate.job import JOB_FILE, plan_evaluation
from farm.evaluate.methods import EvalSettings, HeldOutTree, MethodContext, run_drawn, run_params
from reconstruct import Reconstruction
from reconstruct.fitting import FitRecord, FitTrace
from reconstruct.methods import DEFAULT_FIT_EVALS, METHODS, Input, Method, Rendered
from species import Skeleton, build_mesh

STANDIN = "fit-standin"


def lollipop() -> tuple[Skeleton, object]:
    """A 3 m tree: a 1 m stick (radius 5 cm) under a ball 2 m across, one tube of revolution (leaning 1 cm, so
    that its crown has a radius to compare)."""
    z = np.concatenate([[0.0, 0.5], 1.0 + (1.0 - np.cos(np.linspace(0.02, np.pi - 0.02, 24)))])
    radius = np.maximum(np.where(z <= 1.0, 0.05, np.sqrt(np.clip(1.0 - (z - 2.0) ** 2, 0.0, None))), 0.05)
    n = len(z)
    skeleton = Skeleton(np.stack([np.maximum(z - 1.0, 0.0) / 200.0, np.zeros(n), z], 1).astype(np.float32),
                        np.arange(-1, n - 1, dtype=np.int32), radius.astype(np.float32), np.zeros(n, np.uint8))
    return skeleton, build_mesh(skeleton, {"name": "lollipop", "mesh_radial_segments": [16]})


def pen_drawing(shape: str, filled: bool = False) -> np.ndarray:
    """(256, 256) grey paper with a 2-pixel pen drawing: a lollipop (a circle on a stick, proportioned as
    `lollipop`: the ball two thirds of the height), a conifer (a triangle on a stick) or bare branches (a Y)."""
    paper = np.full((256, 256), 255, np.uint8)
    thickness = -1 if filled else 2
    if shape == "lollipop":
        cv2.circle(paper, (128, 100), 70, 0, thickness)
        cv2.line(paper, (128, 170), (128, 240), 0, 2)
    elif shape == "conifer":
        cv2.polylines(paper, [np.array([[128, 20], [60, 200], [196, 200]], np.int32)], True, 0, 2)
        cv2.line(paper, (128, 200), (128, 240), 0, 2)
    else:  # bare branches: a Y
        cv2.line(paper, (128, 240), (128, 120), 0, 2)
        for tip in ((40, 20), (216, 20)):
            cv2.line(paper, (128, 120), tip, 0, 2)
    return paper


@pytest.fixture(scope="module")
def renderer():
    view_renderer = renderers.ViewRenderer(128)
    yield view_renderer
    view_renderer.close()


@pytest.fixture(scope="module")
def tree(renderer) -> HeldOutTree:
    """The lollipop as a held-out tree whose tsn4 front view holds its mask and its TreeSketchNet sketch."""
    skeleton, mesh = lollipop()
    view = renderer.render(mesh, skeleton, "tsn4", ["mask", "sketch_tsn"], np.random.default_rng(0))[0]
    assert view.name == "front"
    return HeldOutTree("lollipops", "0" * 16, "lollipop-0", "lollipop", {"generator": "colonization"}, skeleton,
                       mesh, {"front": (view.camera, view.images)})


def test_the_sketch_score_fills_a_contour_drawing(renderer):
    skeleton, mesh = lollipop()
    result = Reconstruction("lollipop", skeleton, mesh)
    score = {shape: drawing_fit(result, pen_drawing(shape), renderer).score for shape in ("lollipop", "conifer", "Y")}
    # A circle drawn on a stick is the solid ball on a stick it outlines; other shapes are not.
    assert score["lollipop"] > 0.85
    assert score["conifer"] < 0.6 and score["Y"] < 0.2
    solid = drawing_fit(result, pen_drawing("lollipop", filled=True), renderer).score
    assert abs(solid - score["lollipop"]) < 0.03  # the outline drawn or the shape inked: one score


def _standin(seen: list):
    """A stand-in drawing method that records the budget it is told; a budget gives a fit record."""
    def run(inputs, options) -> Reconstruction:
        seen.append(options.fit_evals)
        skeleton, mesh = lollipop()
        maps = {}
        if options.fit_evals:
            shape = np.ones((128, 40), bool)
            trace = FitTrace([0.25] * (options.fit_evals - 1) + [0.75])
            maps["fit"] = FitRecord(shape, shape, 0.25, shape, 0.75, trace)
        return Reconstruction(STANDIN, skeleton, mesh, maps=maps)

    return run


def test_the_fit_budget_reaches_a_drawing_method_and_its_fit_is_in_the_panel(tree, monkeypatch):
    seen: list[int] = []
    monkeypatch.setitem(METHODS, STANDIN, Method(
        STANDIN, (Input("outline", "image", "a mask", rendered=Rendered("tsn4", "front", "mask")),),
        _standin(seen), options=("fit_evals",)))
    labels = {}
    for evals in (0, 3):
        ctx = MethodContext(None, EvalSettings(surface_samples=0, fit_evals=evals), size=64)
        try:
            labels[evals] = [label for label, _ in run_drawn(STANDIN, tree, ctx).cells]
        finally:
            ctx.close()
    assert seen == [0, 3]
    assert labels[0] == ["input", "reconstruction", "ground truth"]
    assert labels[3] == ["input", "first guess: outline IoU 0.25", "fitted: outline IoU 0.75", "reconstruction",
                         "ground truth"]
    assert EvalSettings().fit_evals == DEFAULT_FIT_EVALS


def test_params_fits_with_the_workers_renderer_within_the_budget(tree, monkeypatch):
    contexts = {evals: MethodContext(None, EvalSettings(surface_samples=0, fit_evals=evals), size=64)
                for evals in (0, 2)}

    def no_new_renderer(*args, **kwargs):
        raise AssertionError("a renderer was made for one tree")

    monkeypatch.setattr(renderers, "ViewRenderer", no_new_renderer)  # what from_params makes one with
    try:
        results = {evals: run_params(tree, ctx) for evals, ctx in contexts.items()}
    finally:
        for ctx in contexts.values():
            ctx.close()
    assert "fit" in results[2].timings and "fit" not in results[0].timings
    labels = [label for label, _ in results[2].cells]
    assert labels[1].startswith("first guess: outline IoU") and labels[2].startswith("fitted: outline IoU")
    assert [label for label, _ in results[0].cells] == ["input", "reconstruction", "ground truth"]


@pytest.fixture
def sketches(tmp_path):
    folder = tmp_path / "sketches"
    folder.mkdir()
    cv2.imwrite(str(folder / "lollipop.png"), pen_drawing("lollipop"))
    return folder


@pytest.mark.parametrize("value", ["-1", "-32"])
def test_a_negative_fit_budget_is_one_line_exit_2_and_nothing_written(sketches, tmp_path, capsys, value):
    out = tmp_path / "report"
    assert main(["evaluate", "--inputs", str(sketches), "--methods", "params", "--fit-evals", value,
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"farm: error: --fit-evals {value} is invalid: allowed an integer >= 0 (0 turns fitting off)"
    assert not out.exists()


def test_a_report_of_another_fit_budget_is_not_resumed(sketches, tmp_path, capsys):
    records = {evals: plan_evaluation([], ["params"], inputs=str(sketches),
                                      settings=EvalSettings(fit_evals=evals)).record for evals in (0, 2)}
    assert records[2] == {**records[0], "settings": {**records[0]["settings"], "fit_evals": 2}}
    out = tmp_path / "report"
    out.mkdir()
    (out / JOB_FILE).write_text(json.dumps(records[0], indent=1, sort_keys=True))
    assert main(["evaluate", "--inputs", str(sketches), "--methods", "params", "--fit-evals", "2",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "holds another evaluation" in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in out.iterdir()) == [JOB_FILE]
