"""The modelling session: edits as pure functions (a refused one changes nothing), undo and redo, the session file
(format, newer versions and non-session files refused) and a reloaded session growing the same tree bytes."""
from __future__ import annotations

import json

import numpy as np
import pytest

from farm.modelling import session as edits
from farm.modelling.lobes import lobe_mesh
from farm.modelling.modelled_tree import growth_parameters, session_glb
from farm.modelling.session import FORMAT_VERSION, History, SessionError, session_from_json, session_to_json

from model_site import ring


def on_polyline(point: np.ndarray, polyline: np.ndarray) -> bool:
    a, b = polyline[:-1], polyline[1:]
    t = np.clip(np.einsum("ij,ij->i", point - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
    return np.linalg.norm(a + t[:, None] * (b - a) - point, axis=1).min() < 1e-9


@pytest.fixture(scope="module")
def modelled():
    """A small model: one lobe from two rings, a trunk and a side branch, one brush stroke."""
    session = edits.new_session("sc_round_maple", seed=7)
    session = edits.add_stroke(session, ring(4.0, 3.0))
    session = edits.add_stroke(session, ring(8.0, 2.5))
    session = edits.make_lobe(session)
    session = edits.add_branch(session, [[0, 0, 0], [0, 0, 2], [0.2, 0, 4]])
    session = edits.add_branch(session, [[0.1, 0, 2], [1, 0, 3], [2, 0, 4]])
    session = edits.add_branch(session, [[0.05, 0, 3], [-1, 0, 4], [-2, 0, 5]])
    return edits.paint(session, [[0, 0, 9], [1, 0, 9.5]], 0.8, 8.0)


def test_edits_build_the_model_and_leave_the_old_state_as_it_was(modelled):
    assert modelled.strokes == () and len(modelled.lobes) == 1 and len(modelled.lobes[0].strokes) == 2
    assert [b.parent for b in modelled.branches] == [-1, 0, 0]  # drawn from on the trunk: grows from it
    base, trunk = modelled.branches[1].points[0], modelled.branches[0].points
    assert np.linalg.norm(base - [0.1, 0, 2]) < 0.2 and on_polyline(base, trunk)  # its base snapped onto the trunk
    assert len(modelled.markers) > 0 and np.all(np.linalg.norm(modelled.markers - [0.5, 0, 9.25], axis=1) < 2)
    with pytest.raises(ValueError):
        modelled.branches[0].points[0, 0] = 1.0  # frozen arrays: a state is never changed in place
    one_stroke = edits.add_stroke(edits.new_session(), ring(3.0, 1.0))
    assert edits.add_stroke(one_stroke, ring(4.0, 1.0)).strokes[0] is one_stroke.strokes[0]
    assert len(one_stroke.strokes) == 1


@pytest.mark.parametrize("edit, message", [
    (lambda s: edits.add_stroke(s, [[0, 0, 0]]), "stroke"),
    (lambda s: edits.add_stroke(s, [[0, 0, 0], [np.nan, 0, 1]]), "finite"),
    (lambda s: edits.make_lobe(s), "at least one"),
    (lambda s: edits.make_lobe(edits.add_stroke(s, [[0, 0, 0], [0, 0, 1], [0, 0, 2]])), "cannot make a lobe"),
    (lambda s: edits.move_subtree(s, 5, np.eye(3), [0, 0, 0]), "branch 5 does not exist"),
    (lambda s: edits.paint(s, [[0, 0, 1]], 0.5, 1e9), "density"),
    (lambda s: edits.set_growth(s, preset="not_a_preset"), "preset 'not_a_preset' is unknown"),
    (lambda s: edits.set_growth(s, parameters={"iterations": 500}), "iterations"),
    (lambda s: edits.set_growth(s, parameters={"max_markers": 400000}), "over the modelling limit"),
])
def test_a_bad_edit_raises_a_named_error_and_the_session_stays(modelled, edit, message):
    before = session_to_json(modelled)
    with pytest.raises(SessionError, match=message):
        edit(modelled)
    assert session_to_json(modelled) == before


def test_a_subtree_move_turns_it_rigidly_and_the_guard_refuses_contact(modelled):
    # Branch 1 (with nothing on it) turned a quarter about its base on the trunk: its tip goes from +x to +y.
    quarter = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    turned = edits.move_subtree(modelled, 1, quarter, [0, 0, 0])
    base = modelled.branches[1].points[0]
    assert np.allclose(turned.branches[1].points - base, (modelled.branches[1].points - base) @ quarter.T)
    assert turned.branches[0] is modelled.branches[0] and turned.branches[2] is modelled.branches[2]
    # Flipped to point down to -x and lifted, branch 1 would cross branch 2: refused, naming both.
    flip = np.diag([-1.0, 1.0, -1.0])
    with pytest.raises(SessionError, match=r"move refused: .*touch \(1 with 2\)"):
        edits.move_subtree(modelled, 1, flip, [0, 0, 3.5])
    assert len(edits.move_subtree(modelled, 1, flip, [0, 2.0, 3.5]).branches) == 3  # beside it: allowed
    # Moving the trunk moves every branch growing from it (its subtree) by the same amount.
    shifted = edits.move_subtree(modelled, 0, np.eye(3), [1.0, 0.0, 0.0])
    assert all(np.allclose(a.points + [1, 0, 0], b.points) for a, b in zip(modelled.branches, shifted.branches))


def test_a_stroke_drag_reshapes_its_span_and_remeshes_the_lobe(modelled):
    stroke = modelled.lobes[0].strokes[1]
    index = len(stroke) // 2
    target = stroke[index] + [0.0, 0.0, 1.0]
    dragged = edits.drag_stroke(modelled, 0, 1, index, target)
    moved = dragged.lobes[0].strokes[1]
    assert np.allclose(moved[index], target, atol=1e-6) and np.array_equal(moved[0], stroke[0])
    # The lobe is remeshed through the dragged stroke: closed, and its surface reaches the target.
    lobe = dragged.lobes[0]
    assert lobe.mesh().is_watertight and np.linalg.norm(lobe.vertices - target, axis=1).min() < 1e-6
    assert np.array_equal(dragged.lobes[0].strokes[0], modelled.lobes[0].strokes[0])  # the other stroke stays


def test_a_stroke_added_to_a_lobe_gives_the_lobe_of_all_its_strokes(modelled):
    extended = edits.make_lobe(edits.add_stroke(modelled, ring(10.0, 1.5)), lobe=0)
    lobe = extended.lobes[0]
    whole = lobe_mesh(list(lobe.strokes))  # from scratch: the local update must agree with it
    assert len(lobe.strokes) == 3 and extended.strokes == ()
    assert np.array_equal(lobe.vertices, whole.vertices) and np.array_equal(lobe.faces, whole.faces)
    assert lobe.vertices[:, 2].max() > modelled.lobes[0].vertices[:, 2].max() + 1.0


def test_undo_and_redo_walk_the_history_and_a_new_edit_drops_the_redo_stack():
    history = History(edits.new_session())
    first = history.apply(edits.add_stroke(history.present, ring(3.0, 1.0)))
    second = first.apply(edits.add_stroke(first.present, ring(5.0, 1.0)))
    assert second.undo().present is first.present and second.undo().undo().present is history.present
    assert second.undo().redo().present is second.present
    branched = second.undo().apply(edits.add_branch(first.present, [[0, 0, 0], [0, 0, 3]]))
    assert branched.future == () and len(branched.present.branches) == 1
    with pytest.raises(SessionError, match="nothing to redo"):
        branched.redo()
    with pytest.raises(SessionError, match="nothing to undo"):
        History(edits.new_session()).undo()


def test_the_session_file_loads_back_to_the_same_state_and_the_same_tree_bytes(modelled):
    text = session_to_json(modelled)
    record = json.loads(text)
    assert record["format"] == "treefarm-model-session" and record["format_version"] == FORMAT_VERSION
    assert set(record) >= {"strokes", "lobes", "branches", "brushes", "preset", "parameters", "seed"}
    loaded = session_from_json(text)
    assert session_to_json(loaded) == text
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(loaded.lobes, modelled.lobes))
    assert np.array_equal(loaded.markers, modelled.markers)
    assert growth_parameters(loaded)["seed"] == 7
    glb = session_glb(modelled)
    assert glb[:4] == b"glTF" and session_glb(loaded) == glb


@pytest.mark.parametrize("text, message", [
    ("not json at all", "not JSON"),
    ('{"format": "treefarm-library"}', "not a modelling session file"),
    ('[1, 2, 3]', "not a modelling session file"),
    ('{"format": "treefarm-model-session", "format_version": 99}', "format version 99, made by a newer treefarm"),
    ('{"format": "treefarm-model-session", "format_version": 1, "strokes": []}', "damaged"),
])
def test_a_file_that_is_not_a_session_or_is_newer_is_refused_by_name(text, message):
    with pytest.raises(SessionError, match=message):
        session_from_json(text)


def test_a_damaged_branch_parent_is_refused(modelled):
    record = json.loads(session_to_json(modelled))
    record["branches"][1]["parent"] = 2
    with pytest.raises(SessionError, match="branch 1 grows from branch 2"):
        session_from_json(json.dumps(record))
