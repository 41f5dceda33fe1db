"""Fitting a reconstruction to its drawing (`reconstruct.fitting`): the outline measure reads contour drawings as
the shapes they enclose, the search never ends worse than its start and keeps to its budget, and the params
method's fit is deterministic, off at budget 0 and better than the first guess on a drawing of a known tree."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

import species
from reconstruct import from_params
from reconstruct.fit_budget import FitError, check_fit_evals
from reconstruct.fitting import (OUTLINE_HEIGHT, TRUNK_WIDER, drawing_outline, fit_params, front_outline,
                                 outline, outline_iou, renderer_at, search, trunk_width)
from reconstruct.networks import predictor
from renderers import ViewRenderer
from trainers.preprocess import ink_mask


def _paper(size: int = 200) -> np.ndarray:
    return np.full((size, size), 255, np.uint8)


def _cloud_on_a_stick(filled: bool) -> np.ndarray:
    """A round crown on a trunk: drawn as pen contours (trunk as two lines open at the foot), or solid."""
    image = _paper()
    thickness = -1 if filled else 2
    cv2.circle(image, (100, 70), 50, 0, thickness)
    if filled:
        cv2.rectangle(image, (92, 115), (108, 190), 0, -1)
    else:
        cv2.line(image, (92, 118), (92, 190), 0, 2)
        cv2.line(image, (108, 118), (108, 190), 0, 2)
    return image


def test_a_contour_drawing_reads_as_the_shape_it_encloses():
    contour, solid = drawing_outline(_cloud_on_a_stick(False)), drawing_outline(_cloud_on_a_stick(True))
    assert contour.shape[0] == OUTLINE_HEIGHT and contour.dtype == bool
    assert outline_iou(contour, solid) > 0.9
    # The crown's inside and the trunk between its two lines are filled, down to the foot.
    assert contour[OUTLINE_HEIGHT // 3, contour.shape[1] // 2]
    assert contour[OUTLINE_HEIGHT - 3, contour.shape[1] // 2]


def test_different_shapes_score_low_and_an_empty_outline_zero():
    tall = _paper()
    cv2.rectangle(tall, (95, 10), (105, 190), 0, -1)
    assert outline_iou(drawing_outline(tall), drawing_outline(_cloud_on_a_stick(True))) < 0.3
    assert outline_iou(outline(np.zeros((20, 20), bool)), drawing_outline(tall)) == 0.0


def test_an_outline_does_not_depend_on_the_drawing_s_size_or_place():
    small = cv2.resize(_cloud_on_a_stick(False), (120, 120), interpolation=cv2.INTER_AREA)
    moved = np.full((300, 260), 255, np.uint8)
    moved[40:240, 10:210] = _cloud_on_a_stick(False)
    reference = drawing_outline(_cloud_on_a_stick(False))
    assert outline_iou(drawing_outline(small), reference) > 0.9
    assert outline_iou(drawing_outline(moved), reference) > 0.97


def test_the_search_keeps_its_budget_never_ends_below_its_start_and_repeats_itself():
    target = np.array([0.8, 0.2, 0.6])
    calls = []

    def score(x):
        calls.append(x.copy())
        return -float(((x - target) ** 2).sum())

    x, value = search(score, np.full(3, 0.5), 25, np.random.default_rng(4))
    assert len(calls) == 25 and np.all((np.array(calls) >= 0) & (np.array(calls) <= 1))
    assert value >= score(np.full(3, 0.5)) and value == pytest.approx(score(x))
    assert value > -0.05  # CMA-ES moves toward the optimum within the budget
    first = [c.tobytes() for c in calls[:25]]
    calls.clear()
    search(score, np.full(3, 0.5), 25, np.random.default_rng(4))
    assert [c.tobytes() for c in calls] == first


def test_a_search_with_its_start_scored_already_spends_nothing_on_it():
    calls = []
    x0 = np.full(2, 0.5)
    x, value = search(lambda x: calls.append(1) or -float(x.sum()), x0, 6, np.random.default_rng(0), x0_score=-1.0)
    assert len(calls) == 6 and value >= -1.0
    # A start better than anything it finds is what comes back.
    x, value = search(lambda x: -10.0, x0, 4, np.random.default_rng(0), x0_score=5.0)
    assert value == 5.0 and np.array_equal(x, x0)


@pytest.mark.parametrize("bad", [-1, 1.5, True, "8", None])
def test_a_budget_that_is_not_a_count_is_refused(bad):
    with pytest.raises(FitError, match="--fit-evals"):
        check_fit_evals(bad)


@pytest.fixture(scope="module")
def known_tree():
    """A cherry the network never saw, drawn in the params method's view: (sketch, skeleton, mesh)."""
    params = species.sample("cherry", np.random.default_rng(23))
    skeleton, mesh = species.rebuild(params)
    renderer = ViewRenderer(256)
    try:
        view = renderer.render(mesh, skeleton, "tsn4", ["sketch_tsn"], np.random.default_rng(0))[0]
    finally:
        renderer.close()
    return view.images["sketch_tsn"], skeleton, mesh


@pytest.fixture(scope="module")
def net():
    return predictor("sketchnet", None)


def test_budget_zero_grows_the_network_s_guess_as_it_is(known_tree, net):
    sketch = known_tree[0]
    result = from_params(sketch, net=net, fit_evals=0)
    outputs, _ = net.outputs_view(sketch)
    assert result.params == net.codec.decode_arrays(dict(outputs), seed=0)[0]
    assert "fit" not in result.maps and "fit" not in result.timings


def test_the_fit_beats_the_first_guess_and_the_same_budget_repeats_itself(known_tree, net, monkeypatch):
    import reconstruct.fitting as fitting

    monkeypatch.setattr(fitting, "FIT_FACES_PER_EVAL", 10**9)  # every evaluation spent (the cap: test below)
    sketch = known_tree[0]
    renderer = ViewRenderer(256)
    try:
        fitted = from_params(sketch, net=net, fit_evals=12, renderer=renderer)
        again = from_params(sketch, net=net, fit_evals=12, renderer=renderer)
        assert renderer.size == 256  # lent at the fit's size, given back as it was
    finally:
        renderer.close()
    record = fitted.maps["fit"]
    assert record.trace.evals == 12 and record.score >= record.first_score
    assert record.score == pytest.approx(max(record.trace.scores)) and record.first_score == record.trace.scores[0]
    assert record.score > 0.6  # the drawing of a preset tree is within reach of the species' own preset
    assert fitted.params == again.params and fitted.mesh.to_glb() == again.mesh.to_glb()
    # The result is the tree the fit grew for the chosen dictionary, the bytes `species.rebuild` gives it.
    assert fitted.mesh.to_glb() == species.rebuild(fitted.params)[1].to_glb()
    assert fitted.maps["species"][0] == fitted.params["species"] and 0.0 <= fitted.maps["species"][1] <= 1.0
    overlay = record.overlay()
    assert overlay.dtype == np.uint8 and overlay.shape[0] == OUTLINE_HEIGHT and overlay[..., 1].any()


def test_a_trunk_drawn_wider_than_the_guess_s_is_fitted_wider(known_tree, net, monkeypatch):
    """The known tree's drawing with its trunk drawn much wider (two lines round it, as people draw trunks): the
    fit tries the guess's trunk at the drawn width and keeps it, a better outline than the trunk it guessed."""
    import reconstruct.fitting as fitting

    monkeypatch.setattr(fitting, "FIT_FACES_PER_EVAL", 10**9)  # the trunk step comes after the species and seeds
    sketch = known_tree[0].copy()
    rows, cols = np.nonzero(ink_mask(sketch))
    foot, height = rows.max(), rows.max() - rows.min()
    middle = int(np.median(cols[rows >= foot - 4]))
    for x in (middle - 30, middle + 30):
        cv2.line(sketch, (x, int(foot - 0.3 * height)), (x, int(foot)), (0, 0, 0), 2)
    target = drawing_outline(sketch)
    outputs, _ = net.outputs_view(sketch)
    guess = net.codec.decode_arrays(dict(outputs), seed=0)[0]
    with renderer_at(None, 224) as renderer:
        guessed = front_outline(renderer, *species.rebuild(guess))
        fit = fit_params(net.codec, dict(outputs), target, 8, 0, renderer)
    assert trunk_width(target) > TRUNK_WIDER * trunk_width(guessed)
    assert fit.params["ratio"] > 1.5 * guess["ratio"]
    assert fit.record.score > outline_iou(guessed, target)


def test_the_fit_stops_at_its_face_budget(known_tree, net, monkeypatch):
    """A count of faces grown and drawn caps the candidates (big crowns cost many times a small one's): past the
    budget no candidate is grown, the guess always is, and the tree given back is the best one grown."""
    import reconstruct.fitting as fitting

    sketch = known_tree[0]
    monkeypatch.setattr(fitting, "FIT_FACES_PER_EVAL", 0)
    alone = from_params(sketch, net=net, fit_evals=12)
    assert alone.maps["fit"].trace.evals == 1
    guess = species.rebuild(alone.params)[1]
    monkeypatch.setattr(fitting, "FIT_FACES_PER_EVAL", (2 * guess.n_faces + 1) / 12)
    few = from_params(sketch, net=net, fit_evals=12)
    assert 2 <= few.maps["fit"].trace.evals < 12
    assert few.mesh.to_glb() == species.rebuild(few.params)[1].to_glb()


def test_a_drawing_s_fit_loads_neither_torch_nor_plotting():
    """The params method in a fresh process: the network through ONNX Runtime, the search through `cma` without
    its plotting and statistics extras (each a second of a drawing's time budget)."""
    code = ("import sys, numpy as np, cv2; from reconstruct import from_params; "
            "image = np.full((200, 200), 255, np.uint8); cv2.circle(image, (100, 70), 50, 0, 2); "
            "cv2.line(image, (95, 118), (95, 190), 0, 2); cv2.line(image, (105, 118), (105, 190), 0, 2); "
            "result = from_params(image, fit_evals=12); assert result.maps['fit'].trace.evals == 12; "
            "loaded = [m for m in ('torch', 'ray', 'matplotlib.pyplot', 'scipy.stats') if m in sys.modules]; "
            "print(loaded)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                          cwd=Path(__file__).resolve().parents[2])
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"
