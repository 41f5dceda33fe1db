"""The sketch-depth method's fit to its drawing: never worse than the guess, today's bytes at budget 0, the same
bytes for the same seed and budget, our own render fitted back to a close outline, bad budgets refused."""
from __future__ import annotations

import contextlib

import numpy as np
import pytest

import reconstruct.fit_sketch_depth as fit_module
import species
from reconstruct.fit_sketch_depth import (FIT_NODE_BUDGET, GUESS_SETTINGS, SKETCH_DEPTH_KNOBS, evaluations_for,
                                          knob_settings, window_iou, window_outline)
from reconstruct.fit_budget import FitError
from reconstruct.fitting import FitRecord
from reconstruct.from_sketch import from_maps
from renderers import ViewRenderer

SIZE = 128
EVALS = 12


@pytest.fixture(scope="module")
def renderer():
    with contextlib.closing(ViewRenderer(SIZE)) as renderer:
        yield renderer


@pytest.fixture(scope="module")
def drawn(renderer):
    """A generated tree's front view of the two-view rig: its true maps stand in for the networks', and its
    coverage, rendered by our own renderer, is the drawing."""
    params = species.sample("sc_round_maple", np.random.default_rng(5))
    skeleton = species.grow(params, np.random.default_rng(params["seed"]))
    mesh = species.build_mesh(skeleton, params)
    view = renderer.render(mesh, skeleton, "two-view", ["silhouette", "trunk_strokes", "trunk_depth", "mask"],
                           np.random.default_rng(0))[0]
    return skeleton, view


def _grown(drawn, renderer, evals, seed=1):
    skeleton, view = drawn
    images = view.images
    return from_maps(images["silhouette"], images["trunk_depth"], images["trunk_strokes"], view.camera,
                     height=skeleton.height, rng=np.random.default_rng(seed), fit_to=images["mask"] > 0,
                     fit_evals=evals, renderer=renderer)


@pytest.fixture(scope="module")
def fitted(drawn, renderer):
    return _grown(drawn, renderer, EVALS)


def test_fit_is_never_worse_than_the_guess_and_records_every_evaluation(fitted):
    record = fitted.maps["fit"]
    assert isinstance(record, FitRecord)
    assert record.trace.evals == EVALS and record.trace.scores[0] == record.first_score
    assert record.score == max(record.trace.scores) >= record.first_score
    assert record.score > record.first_score  # this drawing leaves room to improve on the guess
    assert record.overlay().shape[2] == 3 and "fit" in fitted.timings


def test_budget_zero_gives_the_unfitted_bytes(drawn, renderer, fitted):
    skeleton, view = drawn
    images = view.images
    plain = from_maps(images["silhouette"], images["trunk_depth"], images["trunk_strokes"], view.camera,
                      height=skeleton.height, rng=np.random.default_rng(1))
    off = _grown(drawn, renderer, 0)
    assert off.mesh.to_glb() == plain.mesh.to_glb() and "fit" not in off.maps
    np.testing.assert_array_equal(off.skeleton.positions, plain.skeleton.positions)
    assert fitted.mesh.to_glb() != plain.mesh.to_glb()  # the fit moved the tree
    # the traced main branches stay where they were drawn
    np.testing.assert_array_equal(fitted.maps["main_skeleton"], plain.maps["main_skeleton"])


def test_same_seed_and_budget_give_the_same_bytes(drawn, renderer, fitted):
    again = _grown(drawn, renderer, EVALS)
    assert again.mesh.to_glb() == fitted.mesh.to_glb()
    assert again.maps["fit"].trace.scores == fitted.maps["fit"].trace.scores


def test_our_own_render_is_fitted_back_to_a_close_outline(drawn, renderer, fitted):
    _, view = drawn
    drawing = window_outline(view.images["mask"] > 0)
    ours = window_outline(renderer.silhouette_masks(fitted.mesh, [view.camera])[0])
    # The guess scores about 0.87 here; the fit scores in the growth frame, and the input camera agrees.
    assert window_iou(ours, drawing) >= 0.92 and fitted.maps["fit"].score >= 0.92, (window_iou(ours, drawing),
                                                                                  fitted.maps["fit"].score)


@pytest.mark.parametrize("evals", [-1, True, 2.5, "8"])
def test_a_budget_that_is_not_a_count_is_refused(drawn, renderer, evals):
    with pytest.raises(FitError, match="fit-evals"):
        _grown(drawn, renderer, evals)


def test_knobs_hold_the_guess_at_its_coordinate():
    x0 = np.array([knob.coordinate(knob.guess) for knob in SKETCH_DEPTH_KNOBS])
    assert np.all((x0 > 0) & (x0 < 1))
    np.testing.assert_allclose(list(knob_settings(x0).values()), list(GUESS_SETTINGS.values()), atol=1e-12)


def test_a_large_guess_gets_fewer_evaluations_never_none():
    assert evaluations_for(32, 1000) == 32
    assert evaluations_for(32, FIT_NODE_BUDGET // 8) == 8
    assert evaluations_for(32, 10 * FIT_NODE_BUDGET) == 1  # the guess is always scored
    assert evaluations_for(5, 10) == 5  # never more than asked



def test_the_fit_stops_at_the_node_budget(drawn, renderer, monkeypatch):
    guess_nodes = len(_grown(drawn, renderer, 0).skeleton)
    monkeypatch.setattr(fit_module, "FIT_NODE_BUDGET", 3 * guess_nodes)
    assert _grown(drawn, renderer, EVALS).maps["fit"].trace.evals == 3
